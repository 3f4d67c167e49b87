"""The sheen (``Material.sheen_color``, ``sheen_roughness``; glTF's ``KHR_materials_sheen``):
a layer of the "Charlie" microfibre distribution with Neubelt's visibility over the
material.  Checked pixel by pixel against the formulas written out here in float64 (each
pixel's normal from its ray and the analytic sphere), the sheen's albedo E(n.v) integrated
here by another quadrature than the engine's table: a sun's sheen light, the material under
the sheen keeping 1 - max(sheen) E(n.v), the sheen's reflection of a uniform sky, and a lamp
through a mirror lighting the sheen as a lamp at its image does."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, PointLight, Skybox, Transform, look_rotation
from engine.assets.mesh import quad, sphere
from tests.support import pixel_rays, srgb_to_linear
from tests.test_clearcoat import BLACK_BASE, SIZE, render, sphere_pixels

SUN_TRAVEL = np.array([-0.4, -0.5, -1.0]) / np.linalg.norm([-0.4, -0.5, -1.0])  # ball()'s sun, intensity 0.8


def charlie(alpha: float, cos_h: np.ndarray) -> np.ndarray:
    alpha = max(alpha, 0.002)
    return (2.0 + 1.0 / alpha) * np.maximum(1.0 - cos_h ** 2, 0.0) ** (0.5 / alpha) / (2.0 * math.pi)


def neubelt(nl: np.ndarray, nv: np.ndarray) -> np.ndarray:
    return 1.0 / (4.0 * (nl + nv - nl * nv))


def albedo(roughness: float, nv: np.ndarray, steps: int = 600) -> np.ndarray:
    """E(n.v) = integral of D V n.l over the hemisphere, in theta and phi (sin theta d theta
    d phi; the engine sums in cos theta), by the midpoint rule."""
    theta = (np.arange(steps) + 0.5) / steps * (math.pi / 2.0)
    phi = (np.arange(2 * steps) + 0.5) / (2 * steps) * (2.0 * math.pi)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    l = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    out = []
    for c in np.atleast_1d(nv):
        v = np.array([math.sqrt(1.0 - c * c), 0.0, c])
        h = l + v
        cos_h = h[..., 2] / np.linalg.norm(h, axis=-1)
        f = charlie(roughness * roughness, cos_h) * neubelt(l[..., 2], c) * l[..., 2] * np.sin(t)
        out.append(f.sum() * (math.pi / 2.0 / steps) * (2.0 * math.pi / (2 * steps)))
    return np.array(out)


def surface(view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's unit normal on the sphere, and its unit direction to the eye."""
    eye, rays = pixel_rays(view, SIZE)
    b = (rays * eye).sum(-1)
    t = -b - np.sqrt(np.maximum(b * b - (float(np.dot(eye, eye)) - 1.0), 0.0))
    return eye + t[..., None] * rays, -rays, (eye + t[..., None] * rays)


@pytest.mark.parametrize("roughness", [0.3, 0.7])
def test_a_suns_sheen_light_is_charlie_times_neubelt(scene, roughness):
    """Black base, no sky reflection: the sun's part of the frame (with it less without it)
    is 0.8 x colour x D(h) V n.l at each pixel."""
    sheen = dict(sheen_color=(1.0, 0.5, 0.25), sheen_roughness=roughness)
    lit, view = render(scene, Material(**BLACK_BASE, **sheen), sun=True)
    dark, _ = render(scene, Material(**BLACK_BASE, **sheen))
    inside, nv = sphere_pixels(view)
    normal, to_eye, _ = surface(view)
    l = -SUN_TRAVEL
    nl = np.clip((normal * l).sum(-1), 0.0, 1.0)
    h = to_eye + l
    cos_h = (normal * h).sum(-1) / np.linalg.norm(h, axis=-1)
    expected = 0.8 * charlie(roughness ** 2, cos_h) * neubelt(nl, np.maximum(nv, 1e-4)) * nl
    shown = (lit - dark)[..., 0]
    checked = inside & (nv > 0.25) & (nl > 0.05) & (lit[..., 0] < 0.98)
    assert checked.sum() > 400 and expected[checked].max() > 0.05
    np.testing.assert_allclose(shown[checked], expected[checked], atol=0.006, rtol=0.05)
    np.testing.assert_allclose((lit - dark)[..., 2][checked], 0.25 * expected[checked], atol=0.006, rtol=0.06)


def test_the_material_under_a_sheen_keeps_what_the_sheens_albedo_leaves(scene):
    """A rough red base, lit by the sun and the sky: sheened less the sheen over black is the
    base's light times 1 - max(sheen) E(n.v) (E: the integral above)."""
    red = dict(color=(0.7, 0.1, 0.05, 1.0), roughness=0.9, environment_reflection=0.0)
    sheen = dict(sheen_color=(0.8, 0.8, 0.8), sheen_roughness=0.5)
    sheened_red, view = render(scene, Material(**red, **sheen), sun=True)
    sheened_black, _ = render(scene, Material(**BLACK_BASE, **sheen), sun=True)
    bare_red, _ = render(scene, Material(**red), sun=True)
    bare_black, _ = render(scene, Material(**BLACK_BASE), sun=True)
    inside, nv = sphere_pixels(view, rim=0.06)
    base = (bare_red - bare_black)[..., 0]
    lit = inside & (base > 0.05) & (sheened_red[..., 0] < 0.98)
    assert lit.sum() > 200
    grid = np.linspace(0.02, 1.0, 50)
    share = 1.0 - 0.8 * np.interp(nv, grid, albedo(0.5, grid, 300))
    np.testing.assert_allclose((sheened_red - sheened_black)[..., 0][lit], (base * share)[lit], atol=0.006, rtol=0.03)
    assert share[lit].min() < 0.8 * share[lit].max()   # angles from head on to near grazing


def test_a_sheen_reflects_a_uniform_sky_by_its_albedo(scene):
    """Under a sky of 0.5 everywhere, a sheen over black shows 0.5 x colour x E(n.v)."""
    grey = np.full((6, 8, 8, 3), 0.5, np.float32)

    def build(world):
        from tests.support import look_from
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=grey))
        world.spawn(Transform(), MeshRef(sphere(1.0, 64, 32)),
                    Material(**BLACK_BASE, sheen_color=(1.0, 1.0, 1.0), sheen_roughness=0.6))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())
    inside, nv = sphere_pixels(runner.engine.main_view)
    grid = np.linspace(0.02, 1.0, 50)
    expected = 0.5 * np.interp(nv, grid, albedo(0.6, grid, 300))
    checked = inside & (nv > 0.1)
    assert checked.sum() > 500 and expected[checked].max() > 0.1
    np.testing.assert_allclose(shown[..., 1][checked], expected[checked], atol=0.006, rtol=0.03)


def test_a_lamp_through_a_mirror_lights_a_sheen_as_a_lamp_at_its_image(scene):
    """A mirror that reflects light (out of view on the left) makes a virtual lamp: the
    sheen's light from it (the frame less the one whose mirror reflects no light) equals the
    light of a real lamp where the mirror puts the image (two lamps less one)."""
    lamp, image = (0.5, 0.8, 1.8), (-5.5, 0.8, 1.8)   # the mirror: the plane x = -2.5

    def build(mirror: bool | None, second: bool):
        def made(world):
            from tests.support import look_from
            look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
            world.spawn(Transform(position=lamp), PointLight(intensity=30.0, range=30.0))
            if second:
                world.spawn(Transform(position=image), PointLight(intensity=30.0, range=30.0))
            if mirror is not None:
                world.spawn(Transform(position=(-2.5, 0.0, 1.5), rotation=look_rotation(glm.vec3(-1.0, 0.0, 0.0))),
                            MeshRef(quad(3.0, 4.0)), Material(), Mirror(reflects_light=mirror))
            world.spawn(Transform(), MeshRef(sphere(1.0, 64, 32)),
                        Material(**BLACK_BASE, sheen_color=(1.0, 1.0, 1.0), sheen_roughness=0.4))
        runner = scene(made, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        return srgb_to_linear(runner.frame()), runner.engine.main_view

    through, view = build(True, False)
    unreflected, _ = build(False, False)
    both, _ = build(None, True)
    one, _ = build(None, False)
    inside, _ = sphere_pixels(view)
    virtual, real = (through - unreflected)[inside], (both - one)[inside]
    assert real.max() > 0.05                                  # the image's sheen light, on the left
    np.testing.assert_allclose(virtual, real, atol=0.006)


def test_sheen_values_are_checked():
    with pytest.raises(ComponentValueError, match=r"Material.sheen_color must have every component in \[0, 1\]"):
        Material(sheen_color=(1.5, 0.0, 0.0))
    with pytest.raises(ComponentValueError, match=r"Material.sheen_color"):
        Material(sheen_color=(-0.1, 0.0, 0.0))
    with pytest.raises(ComponentValueError, match=r"Material.sheen_roughness"):
        Material(sheen_roughness=1.2)


def test_the_engines_sheen_albedo_table_is_the_integral():
    """The table the shader reads (held to 1) against the integral above, where it is below 1."""
    from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE, sheen_albedo_table
    table = sheen_albedo_table()
    steps = np.linspace(0.0, 1.0, ENVIRONMENT_BRDF_SIZE)
    for row in (8, 16, 31):
        columns = np.arange(4, ENVIRONMENT_BRDF_SIZE, 4)
        np.testing.assert_allclose(table[row, columns], albedo(steps[row], steps[columns], 300), rtol=0.02, atol=2e-3)
    assert table.max() == 1.0 and table.min() >= 0.0


def test_a_gltf_sheen_reaches_the_material(tmp_path):
    from engine.assets.mesh import load_model
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    def material(sheen: object) -> dict:
        return {"name": "velvet", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.0, 0.1, 1.0]},
                "extensions": {"KHR_materials_sheen": sheen}}
    path = write_glb(tmp_path / "chair.glb", sphere(0.5), material({"sheenColorFactor": [0.9, 0.4, 0.5],
                                                                    "sheenRoughnessFactor": 0.3}), [],
                     {"extensionsUsed": ["KHR_materials_sheen"], "extensionsRequired": ["KHR_materials_sheen"]})
    world = World("chair")
    spawn_model(world, path)
    ((_, velvet),) = list(world.query_one(Material))
    assert list(velvet.sheen_color) == pytest.approx([0.9, 0.4, 0.5]) and velvet.sheen_roughness == pytest.approx(0.3)
    bad = write_glb(tmp_path / "bad.glb", sphere(0.5), material({"sheenColorFactor": [2, 0, 0]}), [])
    with pytest.raises(AssetError, match=r"bad\.glb.*'velvet'.*sheenColorFactor must be three numbers in \[0, 1\]"):
        load_model(bad)
    textured = write_glb(tmp_path / "textured.glb", sphere(0.5),
                         material({"sheenColorFactor": [1, 1, 1], "sheenColorTexture": {"index": 0}}), [])
    with pytest.warns(UserWarning, match=r"'velvet'.*sheenColorTexture left out"):
        load_model(textured)


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_sheen_in_a_mirror_and_through_a_portal_is_shaded_from_that_views_eye(scene, way):
    """A dark ball with a sheen off to the camera's right, seen only in a mirror (or through a
    portal): its sheen, brightest where the ball turns away from the eye, is the frame a camera
    at the mirror's image eye (the eye carried through the portal) draws, turned left for right
    for the mirror (tests/test_clearcoat.py's assert_shown_as_from_its_eye); and the sheen is
    there (the bare ball's frame differs)."""
    from tests.test_clearcoat import assert_shown_as_from_its_eye
    base = dict(color=(0.06, 0.06, 0.1, 1.0), roughness=0.9, environment_reflection=0.0)
    assert_shown_as_from_its_eye(scene, dict(base, sheen_color=(0.9, 0.7, 0.3), sheen_roughness=0.4), base, way)


def test_a_sheen_in_a_probe_face_is_shaded_from_the_probes_centre(scene):
    """The sheened ball off a probe's +X face: the face shows it as a camera at the probe's
    centre looking that way does, texel by texel (tests/test_clearcoat.py's
    assert_probe_face_as_from_its_centre); and the sheen is there."""
    from tests.test_clearcoat import assert_probe_face_as_from_its_centre
    base = dict(color=(0.06, 0.06, 0.1, 1.0), roughness=0.9, environment_reflection=0.0)
    assert_probe_face_as_from_its_centre(scene, dict(base, sheen_color=(0.9, 0.7, 0.3), sheen_roughness=0.4), base)
