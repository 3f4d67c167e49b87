"""Environment specular: a surface without a reflect slot (no Reflective, not a mirror or a
portal) reflects the light from all round, as every engine's default material does: the
sky's radiance along its reflected ray, blurred by its roughness, times the split-sum's
f0 A + B, and its ambient diffuse light takes 1 - (f0 A + B).  Inside a probe's influence box
the sky is scaled by the box's irradiance over the sky's (scene.frag environment_radiance).

The expectations are worked out here on their own: the split-sum integral by quadrature over
a grid of light directions (the engine's table integrates by importance sampling), each
sphere pixel's normal by casting its ray at the analytic sphere in float64, and a white
furnace: a white dielectric under a uniform sky reflects and scatters exactly what arrives."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    ReflectionProbe,
    Reflective,
    Refractive,
    Skybox,
    Transform,
    Visibility,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box, quad, sphere
from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE, environment_brdf_table
from tests.support import linear_to_srgb8, look_from, pixel_rays, srgb_to_linear

SIZE = (200, 120)
EYE = (0.0, 0.0, 6.0)
RADIUS = 0.7
SKY = 0.5  # the uniform sky's linear radiance


# --- independent references -----------------------------------------------------------------------
def quadrature_brdf(roughness: float, nv: float, n: int = 600) -> tuple[float, float]:
    """(A, B) of the split sum by the midpoint rule over a (theta, phi) grid of light
    directions: A = integral (1 - Fc) D V n.l, B = integral Fc D V n.l, Fc = (1 - v.h)^5, D
    the GGX distribution and V the height-correlated Smith visibility over 4 n.l n.v, alpha =
    roughness squared (Walter et al. 2007; Heitz 2014)."""
    a2 = max(roughness * roughness, 1e-4) ** 2
    theta = (np.arange(n) + 0.5) / n * (math.pi / 2)
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    light = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    solid_angle = np.sin(t) * (math.pi / 2 / n) * (math.pi / n)
    view = np.array([math.sqrt(1 - nv * nv), 0.0, nv])
    half = light + view
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    nh, nl, vh = half[..., 2], light[..., 2], np.clip(half @ view, 0.0, 1.0)
    d = a2 / (math.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    v = 1.0 / ((nl + np.sqrt(a2 + (1 - a2) * nl * nl)) * (nv + math.sqrt(a2 + (1 - a2) * nv * nv)))
    fc = (1.0 - vh) ** 5
    base = d * v * nl * solid_angle
    return float(((1 - fc) * base).sum()), float((fc * base).sum())


def sphere_pixels(runner, centre, erode: float = 2.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels whose rays meet the analytic sphere at ``centre`` at least ``erode`` pixels
    inside its silhouette (the mesh's polygons differ at the edge), with n.v and the reflected
    ray there: (mask (h, w), n.v (k,), reflected (k, 3))."""
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    oc = eye - np.asarray(centre, np.float64)
    b = rays @ oc
    c = oc @ oc - RADIUS ** 2
    disc = b * b - c
    # Inside the silhouette by ``erode`` pixels: the ray's distance from the centre against the
    # radius, less the angle ``erode`` pixels span at the sphere's distance.
    pixel = 2.0 * math.tan(math.radians(30.0)) / SIZE[1] * math.sqrt(oc @ oc)
    closest = np.sqrt(np.maximum(c + RADIUS ** 2 - b * b, 0.0))
    mask = (disc > 0) & (closest < RADIUS - erode * pixel)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    normal = (eye + rays * t[..., None] - centre) / RADIUS
    nv = np.einsum("...i,...i", normal, -rays)
    reflected = rays - 2.0 * np.einsum("...i,...i", rays, normal)[..., None] * normal
    return mask, nv[mask], reflected[mask]


def uniform_sky(radiance: float = SKY) -> Skybox:
    return Skybox(faces=np.full((6, 8, 8, 3), radiance, np.float32))


def spheres_scene(materials, sky=None, extra=None, eye=EYE):
    """Spheres of ``materials`` in a row along x, seen head on from ``eye``, under ``sky`` (uniform)."""
    names: dict = {}
    half = 0.8 * (len(materials) - 1)  # 1.6 apart: no sphere hides another's pixels
    xs = np.linspace(-half, half, len(materials))

    def build(world):
        look_from(world, eye, (0.0, 0.0, 0.0), fov=60.0)
        world.spawn(sky if sky is not None else uniform_sky())
        names["spheres"] = [world.spawn(Transform(position=(float(x), 0.0, 0.0)), MeshRef(sphere(RADIUS)), *parts)
                            for x, parts in zip(xs, materials, strict=True)]
        names["centres"] = [(float(x), 0.0, 0.0) for x in xs]
        if extra is not None:
            names.update(extra(world))
    return build, names


def linear_frame(scene, build) -> tuple[np.ndarray, object]:
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner


def srgb_step(linear: np.ndarray, steps: float = 1.5) -> np.ndarray:
    """The linear difference ``steps`` sRGB levels make at ``linear``."""
    return np.abs(srgb_to_linear(np.clip(linear_to_srgb8(linear) + steps, 0, 255)) - linear)


# --- the table ------------------------------------------------------------------------------------
def test_the_environment_brdf_table_is_the_split_sum_integral():
    """The engine's table (importance sampled) against the quadrature here: within 0.02 for
    roughness from 0.25 up and n.v from 0.15 up; at roughness 0 the lobe is a mirror's and
    the integral is Schlick's Fresnel at n.v itself, A = 1 - (1 - n.v)^5, B = (1 - n.v)^5."""
    table = environment_brdf_table()
    last = ENVIRONMENT_BRDF_SIZE - 1
    for row in (8, 12, 16, 22, last):
        for column in (5, 10, 16, 24, last):
            m, nv = row / last, column / last
            np.testing.assert_allclose(table[row, column], quadrature_brdf(m, nv), atol=0.02,
                                       err_msg=f"roughness {m:.3f}, n.v {nv:.3f}")
    nv = np.arange(4, ENVIRONMENT_BRDF_SIZE) / last
    np.testing.assert_allclose(table[0, 4:, 0], 1 - (1 - nv) ** 5, atol=0.02)
    np.testing.assert_allclose(table[0, 4:, 1], (1 - nv) ** 5, atol=0.02)
    # Rough single-scattering GGX loses energy: the albedo A + B falls with roughness.
    assert table[last, last].sum() < table[16, last].sum() < table[0, last].sum()


def test_the_gpu_holds_the_table_below_the_probes_rows(scene):
    runner = scene(spheres_scene([(Material(),)])[0], (32, 24))
    runner.frame()
    np.testing.assert_array_equal(runner.engine.renderer.irradiance.read_environment_brdf(),
                                  environment_brdf_table().astype(np.float64))


# --- what a surface shows ---------------------------------------------------------------------------
def test_white_things_in_a_white_furnace_show_the_sky(scene):
    """A white dielectric under a uniform sky L reflects f0 A + B of it and its diffuse part
    scatters the rest, and a white metal reflects it all (what single scattering loses given
    back as multiple scattering): L everywhere on both, whatever the roughness or angle.
    Without the diffuse's 1 - (f0 A + B) the dielectric would show L (1 + f0 A + B); without
    the multiple scattering a rough metal L (A + B), down to a third of L."""
    roughness = (0.1, 0.5, 1.0)
    white = (1.0, 1.0, 1.0, 1.0)
    build, names = spheres_scene([(Material(color=white, roughness=m, metallic=metal),)
                                  for metal in (0.0, 1.0) for m in roughness])
    linear, runner = linear_frame(scene, build)
    for centre in names["centres"]:
        mask, nv, _ = sphere_pixels(runner, centre, erode=1.5)
        assert mask.sum() > 80
        shown = linear[mask]
        assert np.abs(shown - SKY).max() <= srgb_step(np.array(SKY)) + 0.005, centre


def expected_share(f0: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The share of an even sky a surface of reflectance ``f0`` reflects, from the split sum's
    A and B: single scattering f0 A + B, and the energy 1 - A - B lost to single scattering
    given back in Fdez-Aguera's multiple-scattering term (2019): F_ms E_ms with E_ms the loss,
    F_avg = f0 + (1 - f0) / 21 and F_ms = (f0 A + B) F_avg / (1 - E_ms F_avg)."""
    single = f0 * a[:, None] + b[:, None]
    lost = (1.0 - a - b)[:, None]
    average = f0 + (1.0 - f0) / 21.0
    return single + single * average / (1.0 - lost * average) * lost


def test_clear_glass_in_a_white_furnace_shows_the_sky(scene):
    """A clear white glass ball (Refractive, alpha 0) under a uniform sky L lets through
    1 - F of what is behind it (the sky) and reflects F of the sky along its reflected ray:
    L everywhere on it.  Its reflection is over what it lets through whatever its alpha; were
    it mixed by the alpha as the rest of its light is, its rims (F large) would darken to
    (1 - F) L."""
    build, names = spheres_scene([(Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0), Refractive(ior=1.5))],
                                 eye=(0.0, 0.0, 2.2))
    linear, runner = linear_frame(scene, build)
    mask, nv, _ = sphere_pixels(runner, names["centres"][0])
    assert runner.engine.renderer.resource_counts()["probe_cubes"] == 1  # (its own probe: it reflects that)
    keep = nv < 0.5  # the rims, where F is 0.07 and more
    assert keep.sum() > 300
    assert np.abs(linear[mask][keep] - SKY).max() <= srgb_step(np.array(SKY)) + 0.02


def test_glass_reflects_the_capture_its_refraction_reads(scene):
    """The glass ball's own probe sees a red lamp panel behind the camera, which the camera
    does not: its middle, where the reflected rays go back towards the camera, shows F x the
    panel over (1 - F) x the sky behind it: red over green by about F0 (0.04 for glass) x
    the panel's red less its green (not the sky's reflection, grey)."""
    panel = np.array([5.0, 1.0, 1.0])

    def lamp(world):
        facing_ball = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        return {"panel": world.spawn(Transform(position=(0.0, 0.0, 4.0), rotation=facing_ball),
                                     MeshRef(quad(6.0, 6.0)), Material(color=(1.0, 0.2, 0.2, 1.0)), Emissive(5.0))}

    build, names = spheres_scene([(Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0), Refractive(ior=1.5))],
                                 eye=(0.0, 0.0, 2.2), extra=lamp)
    linear, runner = linear_frame(scene, build)
    mask, nv, _ = sphere_pixels(runner, names["centres"][0])
    middle = linear[mask][nv > 0.97]
    excess = np.median(middle[:, 0] - middle[:, 1])
    assert len(middle) > 30
    assert abs(excess - 0.04 * (panel[0] - panel[1])) < 0.05, excess


def test_a_gold_metal_reflects_the_split_sum_of_its_reflectance(scene):
    """A gold metal (f0 its colour) under a uniform sky L shows L x expected_share at each
    pixel, A and B from the quadrature at that pixel's n.v, channel by channel."""
    gold = np.array([1.0, 0.71, 0.29])
    roughness = (0.3, 0.6, 1.0)
    build, names = spheres_scene([(Material(color=(*gold, 1.0), metallic=1.0, roughness=m),) for m in roughness])
    linear, runner = linear_frame(scene, build)
    for m, centre in zip(roughness, names["centres"], strict=True):
        mask, nv, _ = sphere_pixels(runner, centre)
        samples = np.linspace(0.1, 1.0, 10)
        table = np.array([quadrature_brdf(m, s, n=300) for s in samples])
        a, b = np.interp(nv, samples, table[:, 0]), np.interp(nv, samples, table[:, 1])
        expected = SKY * expected_share(gold, a, b)
        shown = linear[mask]
        keep = nv > 0.15
        error = np.abs(shown[keep] - expected[keep]).max(axis=1)
        assert np.percentile(error, 95) <= srgb_step(expected[keep]).max() + 0.02 * SKY, m
        # Unlike the sky's grey: gold's blue is the least.
        assert np.median(shown[keep][:, 2]) < 0.6 * np.median(shown[keep][:, 0])


def test_a_smooth_metal_shows_the_sky_as_a_sky_reflecting_sphere_does(scene):
    """A mirror-smooth white metal with no Reflective against the same sphere with
    Reflective("skybox", mix=1) (which shows the sky along the reflected ray, tested against
    the sky function elsewhere), under the default generated sky: the same pixels."""
    shown = {}
    for name, parts in (("plain", ()), ("reflective", (Reflective(mode="skybox", mix=1.0),))):
        build, names = spheres_scene([(Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=0.0), *parts)],
                                     sky=Skybox())
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        shown[name] = runner.frame().astype(np.int32)
        mask, nv, _ = sphere_pixels(runner, names["centres"][0])
    keep = mask.copy()
    keep[mask] = nv > 0.2  # Schlick's grazing rise: the table's A + B dips there, the slot's mix does not
    difference = np.abs(shown["plain"] - shown["reflective"]).max(axis=-1)[keep]
    assert keep.sum() > 200
    assert np.percentile(difference, 99) <= 2 and difference.max() <= 4


def test_environment_reflection_scales_the_reflection_and_is_read_live(scene):
    """``Material.environment_reflection`` 0 leaves the old diffuse-only look (a metal black
    under the sky alone), 0.5 is halfway in linear light, and a change to the live component
    is drawn next frame."""
    def material(share):
        return Material(color=(0.9, 0.6, 0.3, 1.0), metallic=1.0, roughness=0.4, environment_reflection=share)

    frames = {}
    for share in (0.0, 0.5, 1.0):
        build, names = spheres_scene([(material(share),)], sky=Skybox())
        frames[share], runner = linear_frame(scene, build)
        mask, _, _ = sphere_pixels(runner, names["centres"][0])
    assert frames[0.0][mask].max() < 0.01  # a metal lit by nothing it can reflect
    assert frames[1.0][mask].mean() > 0.1
    halfway = (frames[0.0][mask] + frames[1.0][mask]) / 2
    assert np.abs(frames[0.5][mask] - halfway).max() <= srgb_step(halfway).max() + 0.002
    runner.world.get(names["spheres"][0], Material).environment_reflection = 0.0
    np.testing.assert_allclose(srgb_to_linear(runner.frame())[mask], frames[0.0][mask], atol=1e-6)


def test_an_occluded_reflection_keeps_lagardes_specular_occlusion(scene):
    """A smooth white metal wall (roughness 0.1) under a uniform sky, half of it occluded to
    0.5 by its occlusion map (strength 0.5): each pixel there over the same pixel of the wall
    without a map is clamp((n.v + ao)^(2^(-16 alpha - 1)) - 1 + ao), alpha = roughness^2
    (Lagarde and de Rousiers 2014): more than the diffuse light's 0.5 for a narrow lobe seen
    nearly head on, and the open half the same as the wall without a map."""
    from tests.test_occlusion_maps import OCCLUSION
    roughness, ao = 0.1, 0.5

    def wall(occluded: bool):
        def build(world):
            look_from(world, (0.0, 1.0, 2.2), (0.0, 1.0, 0.0))
            world.spawn(uniform_sky())
            world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(quad(2.0, 2.0)),
                        Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=roughness,
                                 occlusion_map=OCCLUSION if occluded else None, occlusion_strength=0.5))
        return build

    frames, runner = {}, None
    for occluded in (True, False):
        runner = scene(wall(occluded), SIZE)
        runner.engine.renderer.antialias = "off"
        frames[occluded] = srgb_to_linear(runner.frame()).mean(axis=-1)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = -eye[2] / rays[..., 2]
    points = eye + rays * t[..., None]
    inside = (np.abs(points[..., 0]) < 0.95) & (np.abs(points[..., 1] - 1.0) < 0.95)
    u = (points[..., 0] + 1.0) / 2.0
    left, right = inside & (u > 1 / 8) & (u < 3 / 8), inside & (u > 5 / 8) & (u < 7 / 8)
    nv = -rays[..., 2]
    alpha = roughness ** 2
    expected = np.clip((nv + ao) ** (2.0 ** (-16 * alpha - 1)) - 1 + ao, 0.0, 1.0)
    ratio = frames[True][left] / frames[False][left]
    assert left.sum() > 500 and expected[left].min() > 0.6  # (the diffuse light's share would be 0.5)
    np.testing.assert_allclose(ratio, expected[left], atol=0.02)
    np.testing.assert_allclose(frames[True][right], frames[False][right], atol=1e-6)


def test_the_overlay_switch_turns_them_off_and_on(scene):
    """The prepare stage's ``environment_reflections`` (the overlay's "sky refl"): off, every
    material draws as with environment_reflection 0; the screen line says so; on again, as before."""
    from shell.overlay_text import post_lines

    def materials(share):
        return [(Material(color=(0.9, 0.6, 0.3, 1.0), metallic=1.0, roughness=0.3, environment_reflection=share),),
                (Material(color=(0.2, 0.3, 0.8, 1.0), roughness=0.2, environment_reflection=share),)]

    plain, _ = linear_frame(scene, spheres_scene(materials(0.0), sky=Skybox())[0])
    shown, runner = linear_frame(scene, spheres_scene(materials(1.0), sky=Skybox())[0])
    assert np.abs(shown - plain).max() > 0.1
    runner.engine.stages["prepare"].environment_reflections = False
    np.testing.assert_allclose(srgb_to_linear(runner.frame()), plain, atol=1e-6)
    assert post_lines(runner.engine)[1].endswith("; sky reflections off (set)")
    runner.engine.stages["prepare"].environment_reflections = True
    np.testing.assert_allclose(srgb_to_linear(runner.frame()), shown, atol=1e-6)
    assert "sky reflections" not in post_lines(runner.engine)[1]


def test_a_reflect_slot_decides_alone(scene):
    """A Reflective sphere reflects what its slot says: environment_reflection is not read."""
    frames = []
    for share in (0.0, 1.0):
        build, _ = spheres_scene([(Material(roughness=0.3, environment_reflection=share),
                                   Reflective(mode="skybox", mix=0.4))], sky=Skybox())
        frames.append(linear_frame(scene, build)[0])
    np.testing.assert_array_equal(frames[0], frames[1])


def test_inside_a_probes_box_the_sky_is_scaled_by_the_boxs_light(scene):
    """A dark room a probe captures (walls of albedo 0.1 lit by the sky's irradiance alone, as
    captures are; hidden from the camera) and two smooth white metal spheres, one inside the
    probe's influence box, one outside: under a uniform sky L the box's irradiance is
    pi x 0.1 L in every direction, the sky's pi L, so the inside sphere reflects 0.1 L and
    the outside one L."""
    def room(world):
        hidden = Visibility(direct=False)
        walls = world.spawn(Transform(position=(-1.25, 0.0, 0.0)), MeshRef(box((2.4, 2.4, 2.4))),
                            Material(color=(0.1, 0.1, 0.1, 1.0), roughness=1.0, environment_reflection=0.0,
                                     double_sided=True), hidden)
        probe = world.spawn(Transform(position=(-1.25, 0.0, 0.0)),
                            ReflectionProbe(resolution=16, refresh="once", influence=(2.4, 2.4, 2.4)))
        return {"walls": walls, "probe": probe}

    smooth = (Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=0.0), Visibility(in_probes=False))
    build, names = spheres_scene([smooth, smooth], extra=room)
    # The spheres at x = -1.25 (in the box) and 1.25 (outside it)
    names_positions = ((-1.25, 0.0, 0.0), (1.25, 0.0, 0.0))

    def placed(world):
        build(world)
        for entity, position in zip(names["spheres"], names_positions, strict=True):
            world.get(entity, Transform).position = position
    linear, runner = linear_frame(scene, placed)
    inside_mask, nv, _ = sphere_pixels(runner, names_positions[0])
    outside_mask, _, _ = sphere_pixels(runner, names_positions[1])
    inside = linear[inside_mask].mean(axis=1)
    outside = linear[outside_mask].mean(axis=1)
    assert np.median(np.abs(outside - SKY)) <= srgb_step(np.array(SKY)) + 0.005
    assert np.median(np.abs(inside - 0.1 * SKY)) <= srgb_step(np.array(0.1 * SKY)) + 0.005


@pytest.mark.parametrize("held", [True, False])
def test_a_plain_metal_in_a_probes_box_reflects_its_capture(scene, held):
    """A smooth white metal ball with no Reflective, its middle reflecting straight back
    towards the camera, and a red lamp panel behind the camera that only the probe's capture
    shows: held by the probe's influence box, the ball samples the probe (probe_rules: a plain
    mesh samples the boxes that hold it) and its middle shows the panel's red, sharp; with the
    box elsewhere it reflects the grey sky."""
    colour = np.array([0.5, 0.1, 0.1])
    panel = colour * (1.0 + SKY)  # what the probe sees of it: its emission, and the sky's light on it

    def room(world):
        facing_ball = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        world.spawn(Transform(position=(0.0, 0.0, 4.0), rotation=facing_ball), MeshRef(quad(6.0, 6.0)),
                    Material(color=(*colour, 1.0), environment_reflection=0.0), Emissive(1.0))
        centre = (0.0, 0.0, 0.0) if held else (0.0, 0.0, -20.0)
        return {"probe": world.spawn(Transform(position=centre),
                                     ReflectionProbe(resolution=32, refresh="once", influence=(3.0, 3.0, 3.0)))}

    smooth = (Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=0.0), Visibility(in_probes=False))
    build, names = spheres_scene([smooth], eye=(0.0, 0.0, 2.2), extra=room)
    linear, runner = linear_frame(scene, build)
    mask, nv, _ = sphere_pixels(runner, names["centres"][0])
    middle = np.median(linear[mask][nv > 0.97], axis=0)
    if held:
        np.testing.assert_allclose(middle, panel, atol=0.03)
    else:
        np.testing.assert_allclose(middle, SKY, atol=0.01)


def test_a_still_view_with_a_mirror_keeps_the_probe_reflections_drawn_whole(scene):
    """A mirror, and plain metal and plastic balls in a probe's box reflecting its capture:
    a still camera's kept reflection levels give the frames a whole-drawn engine gives, bit
    for bit (the still tree keeps levels only where nothing they show changed)."""
    from components import Mirror
    from tests.support import kept_frames_equal_drawn

    def build(world):
        look_from(world, (0.0, 0.5, 4.0), (0.0, 0.3, 0.0), fov=60.0)
        world.spawn(Skybox())
        world.spawn(Transform(position=(0.0, 1.0, -2.0)), MeshRef(quad(4.0, 2.0)), Material(), Mirror())
        world.spawn(Transform(position=(0.0, 0.5, 0.0)),
                    ReflectionProbe(resolution=16, refresh="once", influence=(6.0, 4.0, 6.0)))
        world.spawn(Transform(position=(-0.7, 0.3, 0.0)), MeshRef(sphere(0.35)),
                    Material(color=(0.9, 0.7, 0.3, 1.0), metallic=1.0, roughness=0.1))
        world.spawn(Transform(position=(0.7, 0.3, 0.3)), MeshRef(box((0.5, 0.5, 0.5))),
                    Material(color=(0.2, 0.4, 0.8, 1.0), roughness=0.2))

    keeping, drawing = scene(build, (96, 64)), scene(build, (96, 64))
    assert kept_frames_equal_drawn(keeping, drawing, frames=5) >= 2
    assert any(batch.probe for batch in keeping.engine.renderer.batches.values())  # (they sample the probe)


def test_a_world_without_a_sky_reflects_its_hemisphere(scene):
    """No Skybox: the cube is the flat background, so the reflection is the hemisphere's light
    along the ray over pi: a smooth white metal's top reflects nearly the sky colour, its
    bottom nearly the ground's (order-2 harmonics of a hemisphere: E / pi = mix(ground, sky,
    (1 + r.y) / 2), three.js's HemisphereLight, exact)."""
    from components import HemisphereLight
    sky, ground = np.array([0.6, 0.7, 0.9]), np.array([0.2, 0.1, 0.05])

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=60.0)
        world.spawn(HemisphereLight(sky=(*sky, 1.0), ground=(*ground, 1.0)))
        names["sphere"] = world.spawn(Transform(), MeshRef(sphere(RADIUS)),
                                      Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=0.0))
    names: dict = {}
    linear, runner = linear_frame(scene, build)
    mask, nv, reflected = sphere_pixels(runner, (0.0, 0.0, 0.0))
    share = (1.0 + reflected[:, 1:2]) / 2.0
    expected = ground + (sky - ground) * share
    keep = nv > 0.2
    error = np.abs(linear[mask][keep] - expected[keep])
    assert np.percentile(error, 99) <= srgb_step(expected[keep]).max() + 0.01


# --- the component ------------------------------------------------------------------------------
def test_environment_reflection_is_checked_and_saved(tmp_path):
    with pytest.raises(ComponentValueError, match="environment_reflection"):
        Material(environment_reflection=1.5)
    with pytest.raises(ComponentValueError, match="environment_reflection"):
        Material(environment_reflection=float("nan"))
    from engine.core.world import World
    (tmp_path / "room.toml").write_text("""
[level]
name = "room"

[[entity]]
name = "ball"
Transform = { position = [0.0, 1.0, 0.0] }
MeshRef = { mesh = { sphere = 0.5 } }
Material = { color = [0.8, 0.8, 0.8, 1.0], metallic = 1.0, environment_reflection = 0.25 }
""")
    world = World()
    names = load_level(tmp_path / "room.toml").spawn(world)
    assert world.get(names["ball"], Material).environment_reflection == 0.25
    saved = save_level(world, tmp_path / "again.toml", names, name="room")
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["ball"], Material).environment_reflection == 0.25
    (tmp_path / "bad.toml").write_text((tmp_path / "room.toml").read_text().replace("0.25", "-1.0"))
    with pytest.raises(LevelError, match="environment_reflection"):
        load_level(tmp_path / "bad.toml")


# --- the lights' highlights -------------------------------------------------------------------------
def ggx_highlight(normal: np.ndarray, view: np.ndarray, light: np.ndarray, f0: np.ndarray,
                  roughness: float) -> np.ndarray:
    """Single-scattering GGX (Walter et al. 2007) with Schlick's Fresnel and the height-
    correlated Smith visibility (Heitz 2014) times n.l, for unit ``normal`` and ``view`` rows
    and one unit ``light`` (towards the light), written out in float64."""
    a2 = max(roughness * roughness, 1e-4) ** 2
    half = view + light
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    nh, nl = np.einsum("ij,ij->i", normal, half), normal @ light
    nv = np.einsum("ij,ij->i", normal, view)
    vh = np.clip(half @ light, 0.0, 1.0)
    d = a2 / (math.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    v = 1.0 / ((nl + np.sqrt(a2 + (1 - a2) * nl * nl)) * (nv + np.sqrt(a2 + (1 - a2) * nv * nv)))
    fresnel = f0 + (1.0 - f0) * ((1.0 - vh) ** 5)[:, None]
    return fresnel * (d * v * np.maximum(nl, 0.0))[:, None]


def test_a_rough_metals_highlight_keeps_the_light_single_scattering_loses(scene):
    """A sun on white and gold metals, roughness 0.6 to 1, under a black sky: each pixel is
    the sun's GGX highlight times 1 + f0 (1 / (A + B) - 1) (Kulla and Conty's energy
    compensation, in Filament's form), A + B from the quadrature at its n.v: for a white
    metal the highlight a white furnace of suns would sum to the light they send, as the sky's
    reflection does.  Single scattering alone is a quarter to a third darker at roughness 1."""
    sun = np.array([0.3, 0.5, 1.0]) / np.linalg.norm([0.3, 0.5, 1.0])  # towards the sun
    metals = [(np.array([1.0, 1.0, 1.0]), 0.6), (np.array([1.0, 1.0, 1.0]), 1.0), (np.array([1.0, 0.71, 0.29]), 0.8)]

    def light(world):
        world.spawn(DirectionalLight(direction=tuple(-sun), intensity=1.0, shadows=False))
        return {}

    build, names = spheres_scene([(Material(color=(*f0, 1.0), metallic=1.0, roughness=m),) for f0, m in metals],
                                 sky=uniform_sky(0.0), extra=light)
    linear, runner = linear_frame(scene, build)
    _, rays = pixel_rays(runner.engine.main_view, SIZE)
    for (f0, m), centre in zip(metals, names["centres"], strict=True):
        mask, nv, reflected = sphere_pixels(runner, centre)
        # The normal from the reflected ray: r = 2 (n.v) n - v, so n = (r + v) / (2 n.v).
        view = -rays[mask]
        normal = (reflected + view) / (2.0 * nv[:, None])
        samples = np.linspace(0.05, 1.0, 20)
        table = np.array([quadrature_brdf(m, s, n=300) for s in samples])
        single_white = np.interp(nv, samples, table[:, 0] + table[:, 1])
        single = ggx_highlight(normal, view, sun, f0, m)
        expected = single * (1.0 + f0 * (1.0 / single_white[:, None] - 1.0))
        keep = (normal @ sun > 0.25) & (nv > 0.2)
        shown = linear[mask][keep]
        error = np.abs(shown - expected[keep]).max(axis=1)
        assert keep.sum() > 100
        assert np.percentile(error, 95) <= srgb_step(expected[keep]).max() + 0.01, (m, np.percentile(error, 95))
        # ... and not single scattering alone (a fifth and more below it, rough white metal).
        if m == 1.0:
            assert np.median(shown[:, 0] / expected[keep][:, 0]) > 0.97
            assert np.median(single[keep][:, 0] / expected[keep][:, 0]) < 0.8
