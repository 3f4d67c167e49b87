"""Anisotropy (``Material.anisotropy``, ``anisotropy_direction``; glTF's
``KHR_materials_anisotropy``): GGX highlights stretched along a direction of the surface.
A brushed metal floor under a lamp, checked pixel by pixel against the highlight written out
here in float64 (Burley's anisotropic GGX and the separable Smith visibility, alpha_t =
mix(alpha, 1, anisotropy^2) along the direction, alpha_b = alpha across it, the lamp's
falloff and the engine's energy compensation from the split-sum integral), the isotropic
floor against the same formulas at anisotropy 0; a lamp through a mirror lights it as a lamp
at its image does; under a uniform sky the bent reflection reads what the plain one does."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, PointLight, Skybox, Transform, look_rotation
from engine.assets.mesh import Mesh, plane, quad
from tests.support import look_from, pixel_rays, split_sum, srgb_to_linear

SIZE = (96, 72)
EYE, LAMP, INTENSITY, RANGE = (0.0, 2.0, 3.0), np.array([0.3, 1.0, 0.5]), 3.0, 20.0
ROUGHNESS = 0.35


def mirrored_uv_plane(size: float) -> Mesh:
    """The plane with its u running the other way (+u along -x, +v still along -z): the UVs of
    a model's mirrored half, whose tangent frame is left-handed."""
    flat = plane(size, size)
    uvs = flat.uvs.copy()
    uvs[:, 0] = 1.0 - uvs[:, 0]
    return Mesh(flat.positions.copy(), flat.normals.copy(), uvs, flat.indices.copy(), name="mirrored uv plane")


def floor_frame(scene, anisotropy: float, direction: float, mirrored: bool = False):
    """The lit brushed floor (a white metal, its sky reflection off) under the lamp; ``mirrored``:
    its UVs' u turned round."""
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Transform(position=tuple(LAMP)), PointLight(intensity=INTENSITY, range=RANGE))
        world.spawn(Transform(), MeshRef(mirrored_uv_plane(8.0) if mirrored else plane(8.0, 8.0)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=ROUGHNESS, environment_reflection=0.0,
                             anisotropy=anisotropy, anisotropy_direction=direction))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())[..., 1], runner.engine.main_view


def expected_highlight(view, anisotropy: float, direction: float, mirrored: bool = False) -> np.ndarray:
    """Each pixel's highlight: F (1: a white metal) D V n.l x the lamp's light x 1 / (A + B).
    ``mirrored``: the plane's +u runs along -x, its +v still along -z (glTF's bitangent, the
    tangent's w -1: the direction still turns from +u towards +v)."""
    eye, rays = pixel_rays(view, SIZE)
    p = eye + (-eye[1] / rays[..., 1])[..., None] * rays          # where each ray meets y = 0
    n = np.array([0.0, 1.0, 0.0])
    u, w = np.array([-1.0 if mirrored else 1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])  # the plane's +u and +v
    t = math.cos(math.radians(direction)) * u + math.sin(math.radians(direction)) * w
    b = np.cross(n, t)
    to_lamp = LAMP - p
    d = np.linalg.norm(to_lamp, axis=-1)
    l = to_lamp / d[..., None]
    v = (eye - p) / np.linalg.norm(eye - p, axis=-1)[..., None]
    h = (l + v) / np.linalg.norm(l + v, axis=-1)[..., None]
    alpha = ROUGHNESS ** 2
    at, ab = alpha + (1.0 - alpha) * anisotropy ** 2, alpha
    dot = lambda x, y: (x * y).sum(-1)   # noqa: E731
    nl, nv = dot(l, n), dot(v, n)
    a2 = at * ab
    dvec = np.stack([ab * dot(t, h), at * dot(b, h), a2 * dot(n, h)], -1)
    D = a2 * (a2 / (dvec ** 2).sum(-1)) ** 2 / math.pi
    gl = nl + np.sqrt((at * dot(t, l)) ** 2 + (ab * dot(b, l)) ** 2 + nl ** 2)
    gv = nv + np.sqrt((at * dot(t, v)) ** 2 + (ab * dot(b, v)) ** 2 + nv ** 2)
    fade = np.clip(1.0 - (d / RANGE) ** 4, 0.0, 1.0) ** 2
    split = split_sum(ROUGHNESS, nv).sum(-1)
    return D / (gl * gv) * nl * INTENSITY * fade / (d * d + 1.0) / split


@pytest.mark.parametrize("anisotropy, direction, mirrored", [(0.0, 0.0, False), (0.8, 0.0, False), (0.8, 90.0, False),
                                                              (0.6, 30.0, False), (0.6, 30.0, True)])
def test_a_brushed_floors_highlight_is_anisotropic_ggx(scene, anisotropy, direction, mirrored):
    """``mirrored``: on UVs whose u runs the other way the direction still turns from +u
    towards +v (not towards n x u, which is -v there)."""
    shown, view = floor_frame(scene, anisotropy, direction, mirrored)
    expected = expected_highlight(view, anisotropy, direction, mirrored)
    checked = (expected > 0.03) & (shown < 0.97)
    assert checked.sum() > 150
    np.testing.assert_allclose(shown[checked], expected[checked], rtol=0.05, atol=0.01)
    if anisotropy:   # stretched: lit where the round highlight is not
        round_ = expected_highlight(view, 0.0, 0.0)
        assert ((shown > 0.1) & (round_ < 0.02)).sum() > 40


def test_a_lamp_through_a_mirror_lights_a_brushed_floor_as_a_lamp_at_its_image(scene):
    """Looking along -x at a mirror (the plane x = -4) that reflects light: the floor's light
    from the lamp's image (the frame less the one whose mirror reflects none) equals a real
    lamp's at the image (two lamps less one), where the line to the image passes through the
    mirror, and is nothing where it does not."""
    eye, lamp, image = (2.0, 2.0, 0.5), (0.3, 3.5, 0.5), np.array([-8.3, 3.5, 0.5])

    def frame(mirror: bool | None, second: bool):
        def build(world):
            look_from(world, eye, (-2.0, 0.0, 0.5), fov=50.0)
            world.spawn(Transform(position=lamp), PointLight(intensity=40.0, range=RANGE))
            if second:
                world.spawn(Transform(position=tuple(image)), PointLight(intensity=40.0, range=RANGE))
            if mirror is not None:
                world.spawn(Transform(position=(-4.0, 3.0, 0.5), rotation=look_rotation(glm.vec3(-1.0, 0.0, 0.0))),
                            MeshRef(quad(4.0, 3.0)), Material(), Mirror(reflects_light=mirror))
            world.spawn(Transform(), MeshRef(plane(16.0, 16.0)),
                        Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=ROUGHNESS,
                                 environment_reflection=0.0, anisotropy=0.8, anisotropy_direction=90.0))
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        return srgb_to_linear(runner.frame())[..., 1], runner.engine.main_view

    through, view = frame(True, False)
    unreflected, _ = frame(False, False)
    both, _ = frame(None, True)
    one, _ = frame(None, False)
    virtual, real = through - unreflected, both - one
    origin, rays = pixel_rays(view, SIZE)
    p = origin + (-origin[1] / np.minimum(rays[..., 1], -1e-6))[..., None] * rays   # the floor
    cross = p + ((-4.0 - p[..., 0]) / (image[0] - p[..., 0]))[..., None] * (image - p)
    floor = (rays[..., 1] < 0) & (p[..., 0] > -3.8)       # in front of the mirror, not behind it
    inside = floor & (np.abs(cross[..., 2] - 0.5) < 1.9) & (np.abs(cross[..., 1] - 3.0) < 1.4)
    outside = floor & ((np.abs(cross[..., 2] - 0.5) > 2.1) | (np.abs(cross[..., 1] - 3.0) > 1.6))
    assert real[inside].max() > 0.05 and inside.sum() > 300
    np.testing.assert_allclose(virtual[inside], real[inside], atol=0.008)
    assert np.abs(virtual[outside]).max() < 0.008


def test_under_a_uniform_sky_the_bent_reflection_reads_what_the_plain_one_does(scene):
    """Ball-less: a rough metal floor under a sky of 0.4 everywhere reflects 0.4 x its split
    sum whichever ray it reads along."""
    grey = np.full((6, 8, 8, 3), 0.4, np.float32)
    frames = []
    for anisotropy in (0.0, 0.9):
        def build(world, anisotropy=anisotropy):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=50.0)
            world.spawn(Skybox(faces=grey))
            world.spawn(Transform(), MeshRef(plane(8.0, 8.0)),
                        Material(color=(0.9, 0.9, 0.9, 1.0), metallic=1.0, roughness=0.5, anisotropy=anisotropy))
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frames.append(srgb_to_linear(runner.frame()))
    floor = frames[0][..., 1] > 0.1
    assert floor.sum() > 1000
    np.testing.assert_allclose(frames[1][floor], frames[0][floor], atol=0.008)


def test_anisotropy_values_are_checked_and_read_from_gltf(tmp_path):
    with pytest.raises(ComponentValueError, match=r"Material.anisotropy"):
        Material(anisotropy=1.5)
    with pytest.raises(ComponentValueError, match=r"Material.anisotropy_direction"):
        Material(anisotropy_direction=float("nan"))
    from engine.assets.mesh import load_model, sphere
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    def material(info: object) -> dict:
        return {"name": "brushed", "pbrMetallicRoughness": {"metallicFactor": 1.0, "roughnessFactor": 0.4},
                "extensions": {"KHR_materials_anisotropy": info}}
    path = write_glb(tmp_path / "pan.glb", sphere(0.5), material({"anisotropyStrength": 0.7,
                                                                  "anisotropyRotation": math.pi / 6}), [],
                     {"extensionsRequired": ["KHR_materials_anisotropy"]})
    world = World("pan")
    spawn_model(world, path)
    ((_, brushed),) = list(world.query_one(Material))
    assert brushed.anisotropy == pytest.approx(0.7) and brushed.anisotropy_direction == pytest.approx(30.0)
    bad = write_glb(tmp_path / "bad.glb", sphere(0.5), material({"anisotropyStrength": 2}), [])
    with pytest.raises(AssetError, match=r"bad\.glb.*'brushed'.*anisotropyStrength must be a number in \[0, 1\]"):
        load_model(bad)
    textured = write_glb(tmp_path / "textured.glb", sphere(0.5),
                         material({"anisotropyStrength": 1, "anisotropyTexture": {"index": 0}}), [])
    with pytest.warns(UserWarning, match=r"'brushed'.*anisotropyTexture left out"):
        load_model(textured)


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_brushed_ball_in_a_mirror_and_through_a_portal_is_shaded_from_that_views_eye(scene, way):
    """A brushed metal ball off to the camera's right, seen only in a mirror (or through a
    portal): its stretched highlight and its bent reflection of the sky are the frame a camera
    at the mirror's image eye (the eye carried through the portal) draws, turned left for right
    for the mirror (tests/test_clearcoat.py's assert_shown_as_from_its_eye; the frame from the
    UVs' derivatives is the same either way round); and the anisotropy is there (the isotropic
    ball's frame differs)."""
    from tests.test_clearcoat import assert_shown_as_from_its_eye
    base = dict(color=(0.9, 0.85, 0.8, 1.0), metallic=1.0, roughness=0.3)
    assert_shown_as_from_its_eye(scene, dict(base, anisotropy=0.9, anisotropy_direction=30.0), base, way)


def test_a_brushed_ball_in_a_probe_face_is_shaded_from_the_probes_centre(scene):
    """The brushed metal ball off a probe's +X face: the face shows it as a camera at the
    probe's centre looking that way does, texel by texel (tests/test_clearcoat.py's
    assert_probe_face_as_from_its_centre); and the anisotropy is there."""
    from tests.test_clearcoat import assert_probe_face_as_from_its_centre
    base = dict(color=(0.9, 0.85, 0.8, 1.0), metallic=1.0, roughness=0.3)
    assert_probe_face_as_from_its_centre(scene, dict(base, anisotropy=0.9, anisotropy_direction=30.0), base)
