"""Thin-film iridescence (``Material.iridescence``, ``iridescence_ior``,
``iridescence_thickness``; glTF's ``KHR_materials_iridescence``): Belcour and Barla's
model.  A black dielectric ball with a film, under a uniform sky, checked pixel by pixel
against the film's reflectance computed here in float64 (the Airy sum of the film's round
trips, its spectrum integrated against the CIE curves' Gaussian fit, to Rec.709), turned
into the F0 Schlick's form gives it at n.v and reflected by the split sum; a film of no
thickness draws what no film does (a second path); glTF reading."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components import ComponentValueError, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import sphere
from engine.render.environment_brdf import environment_brdf
from tests.support import look_from, srgb_to_linear
from tests.test_clearcoat import SIZE, sphere_pixels

SKY = 0.6
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])


def fringe(opd: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """Rec.709 of the cosine spectrum of optical path difference ``opd`` (nm, (n,)) and phase
    ``shift`` ((n, 3)): the CIE curves' Gaussian fit (Belcour and Barla 2017) in closed form."""
    k = 2.0 * math.pi * opd[:, None] * 1e-9
    height = np.array([5.4856e-13, 4.4201e-13, 5.2481e-13])
    centre = np.array([1.6810e6, 1.7953e6, 2.2084e6])
    spread = np.array([4.3278e9, 9.3046e9, 6.6121e9])
    xyz = height * np.sqrt(2 * math.pi * spread) * np.cos(centre * k + shift) * np.exp(-spread * k ** 2)
    xyz[:, 0] += 9.7470e-14 * math.sqrt(2 * math.pi * 4.5282e9) * np.cos(2.2399e6 * k[:, 0] + shift[:, 0]) \
        * np.exp(-4.5282e9 * k[:, 0] ** 2)
    return (xyz / 1.0685e-7) @ XYZ_TO_REC709.T


def film_f0(nv: np.ndarray, index: float, thickness: float, base_f0: float = 0.04) -> np.ndarray:
    """The F0 whose Schlick curve meets the film's reflectance at each n.v ((n, 3))."""
    schlick = lambda f0, c: f0 + (1 - f0) * (1 - c) ** 5   # noqa: E731
    sin2 = (1 - nv ** 2) / index ** 2
    cos2 = np.sqrt(1 - sin2)
    r12 = schlick(((index - 1) / (index + 1)) ** 2, nv)
    t121 = 1 - r12
    base = (1 + math.sqrt(base_f0)) / (1 - math.sqrt(base_f0))
    r23 = schlick(((base - index) / (base + index)) ** 2, cos2)
    shift = math.pi + (math.pi if base < index else 0.0)   # the top's on the way out, the base's
    r123 = np.clip(r12 * r23, 1e-5, 0.9999)
    inside = t121 ** 2 * r23 / (1 - r123)
    total = (r12 + inside)[:, None] * np.ones(3)
    order = inside - t121
    for m in (1, 2):
        order = order * np.sqrt(r123)
        total += order[:, None] * 2 * fringe(m * 2 * index * thickness * cos2, np.full((len(nv), 3), m * shift))
    reflectance = np.maximum(total, 0.0)
    grazing = ((1 - nv) ** 5)[:, None]
    return np.clip((reflectance - grazing) / (1 - grazing), 0.0, 1.0)


def ball(scene, **film) -> tuple[np.ndarray, object]:
    def build(world):
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=np.full((6, 8, 8, 3), SKY, np.float32)))
        world.spawn(Transform(), MeshRef(sphere(1.0, 64, 32)),
                    Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3, **film))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner.engine.main_view


@pytest.mark.parametrize("thickness", [300.0, 550.0])
def test_a_films_colours_are_belcour_and_barlas_reflectance(scene, thickness):
    shown, view = ball(scene, iridescence=1.0, iridescence_ior=1.3, iridescence_thickness=thickness)
    inside, nv = sphere_pixels(view)
    checked = inside & (nv > 0.2)
    f0 = film_f0(nv[checked], 1.3, thickness)
    a, b = np.moveaxis(environment_brdf(0.3, nv[checked]), -1, 0)
    single = f0 * a[:, None] + b[:, None]
    lost = (1 - a - b)[:, None]
    average = f0 + (1 - f0) / 21
    expected = SKY * (single + single * average / (1 - lost * average) * lost)   # scene.frag environment_share
    assert checked.sum() > 1000
    np.testing.assert_allclose(shown[checked], expected, rtol=0.04, atol=0.006)
    assert np.ptp(f0, axis=0).max() > 0.02 and np.abs(f0[:, 0] - f0[:, 2]).max() > 0.02   # colours, changing


def test_a_film_of_no_thickness_draws_what_no_film_does(scene):
    bare, _ = ball(scene)
    vanished, _ = ball(scene, iridescence=1.0, iridescence_thickness=0.0)
    coloured, _ = ball(scene, iridescence=1.0, iridescence_thickness=400.0)
    np.testing.assert_allclose(vanished, bare, atol=0.006)
    assert np.abs(coloured - bare).max() > 0.03


def test_iridescence_values_are_checked_and_read_from_gltf(tmp_path):
    for field, value in (("iridescence", 1.2), ("iridescence_ior", 0.5), ("iridescence_thickness", -1.0)):
        with pytest.raises(ComponentValueError, match=rf"Material.{field}"):
            Material(**{field: value})
    from engine.assets.mesh import load_model
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    def material(info: object) -> dict:
        return {"name": "bubble", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
                "extensions": {"KHR_materials_iridescence": info}}
    path = write_glb(tmp_path / "bubble.glb", sphere(0.5), material({"iridescenceFactor": 1.0, "iridescenceIor": 1.4,
                                                                     "iridescenceThicknessMaximum": 500}), [],
                     {"extensionsRequired": ["KHR_materials_iridescence"]})
    world = World("bubble")
    spawn_model(world, path)
    ((_, bubble),) = list(world.query_one(Material))
    assert (bubble.iridescence, bubble.iridescence_ior, bubble.iridescence_thickness) == pytest.approx((1.0, 1.4, 500))
    bad = write_glb(tmp_path / "bad.glb", sphere(0.5), material({"iridescenceFactor": 2}), [])
    with pytest.raises(AssetError, match=r"bad\.glb.*'bubble'.*iridescenceFactor must be a number in \[0, 1\]"):
        load_model(bad)
    textured = write_glb(tmp_path / "textured.glb", sphere(0.5),
                         material({"iridescenceFactor": 1, "iridescenceThicknessTexture": {"index": 0}}), [])
    with pytest.warns(UserWarning, match=r"'bubble'.*iridescenceThicknessTexture left out"):
        load_model(textured)


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_film_in_a_mirror_and_through_a_portal_is_coloured_by_that_views_angle(scene, way):
    """A black ball with a film off to the camera's right, seen only in a mirror (or through a
    portal): its colours, which turn with n.v, are the frame a camera at the mirror's image eye
    (the eye carried through the portal) draws, turned left for right for the mirror
    (tests/test_clearcoat.py's assert_shown_as_from_its_eye); and the film is there (the bare
    ball's frame differs)."""
    from tests.test_clearcoat import assert_shown_as_from_its_eye
    base = dict(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3)
    assert_shown_as_from_its_eye(scene, dict(base, iridescence=1.0, iridescence_thickness=450.0), base, way, by=0.01)


def test_a_film_in_a_probe_face_is_coloured_by_the_angle_from_the_probes_centre(scene):
    """The black ball with a film off a probe's +X face: the face shows its colours as a camera
    at the probe's centre looking that way does, texel by texel (tests/test_clearcoat.py's
    assert_probe_face_as_from_its_centre); and the film is there."""
    from tests.test_clearcoat import assert_probe_face_as_from_its_centre
    base = dict(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3)
    assert_probe_face_as_from_its_centre(scene, dict(base, iridescence=1.0, iridescence_thickness=450.0), base,
                                         by=0.01)
