"""Diffuse transmission (``Material.diffuse_transmission``, glTF's
``KHR_materials_diffuse_transmission``): a thin sheet lit only from behind shows on its front
what the same sheet made opaque in the transmission's colour shows lit from the front by the
light mirrored through it (the back's Lambert, a second path); lit from the front it
scatters the rest of its light (1 - share: an opaque sheet of albedo x (1 - share)); a
shadow behind it reaches its front; read from glTF; bad values refused."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Material, MeshRef, PointLight, Transform
from engine.assets.mesh import box, quad, sphere
from engine.core.color import srgb_to_linear
from tests.support import look_from

COLOUR = (0.9, 0.5, 0.2)
BEHIND = glm.normalize(glm.vec3(0.3, -0.2, 1.0))    # travelling towards the camera: lights the sheet's back
IN_FRONT = glm.vec3(BEHIND.x, BEHIND.y, -BEHIND.z)  # the same light mirrored through the sheet


def sheet(material: Material, light: glm.vec3, blocker: bool = False, lamp: bool = False):
    """A 2 m sheet facing the camera (its front +z), one sun (``lamp``: a lamp 1.5 m up the
    way the sun's light comes from), nothing else lit; ``blocker``: a box between the sun and
    the sheet's back, its shadow on the back."""
    def build(world):
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
        if lamp:
            world.spawn(Transform(position=-light * 1.5), PointLight(intensity=6.0, range=20.0))
        else:
            world.spawn(DirectionalLight(direction=light, intensity=3.0))
        world.spawn(Transform(), MeshRef(quad(2.0, 2.0)), material)
        if blocker:
            world.spawn(Transform(position=glm.vec3(0.0) - BEHIND * 1.5), MeshRef(box((0.6, 0.6, 0.1))),
                        Material(color=(0.1, 0.1, 0.1, 1.0)))
    return build


def linear_middle(scene, build) -> np.ndarray:
    runner = scene(build, (96, 72))
    runner.frame()
    image = runner.frame()
    return srgb_to_linear(image[28:44, 40:56].reshape(-1, 3).astype(np.float64) / 255.0)


def plain(**fields) -> Material:
    """No highlight, no reflection (reflectance 0, rough): only the scattered light shows."""
    return Material(**{"reflectance": 0.0, "roughness": 1.0, "environment_reflection": 0.0, **fields})


@pytest.mark.parametrize("lamp", [False, True])
def test_lit_from_behind_the_front_shows_the_backs_lambert_in_its_colour(scene, lamp):
    through = linear_middle(scene, sheet(plain(color=(0.3, 0.3, 0.3, 1.0), diffuse_transmission=1.0,
                                               diffuse_transmission_color=COLOUR), BEHIND, lamp=lamp))
    opaque = linear_middle(scene, sheet(plain(color=(*COLOUR, 1.0)), IN_FRONT, lamp=lamp))
    dark = linear_middle(scene, sheet(plain(color=(*COLOUR, 1.0)), BEHIND, lamp=lamp))
    np.testing.assert_allclose(through.mean(axis=0), opaque.mean(axis=0), rtol=0.04, atol=0.004)
    assert through.mean() > dark.mean() + 0.1   # (an opaque sheet lit from behind is dark)


def test_lit_from_the_front_it_scatters_what_it_does_not_let_through(scene):
    """Half let through (in black: what passes from the light all round behind adds nothing
    here) leaves half scattered in front: as an opaque sheet of half the albedo."""
    half = linear_middle(scene, sheet(plain(color=(*COLOUR, 1.0), diffuse_transmission=0.5,
                                            diffuse_transmission_color=(0.0, 0.0, 0.0)), IN_FRONT))
    dimmer = linear_middle(scene, sheet(plain(color=(0.5 * COLOUR[0], 0.5 * COLOUR[1], 0.5 * COLOUR[2], 1.0)),
                                        IN_FRONT))
    np.testing.assert_allclose(half.mean(axis=0), dimmer.mean(axis=0), rtol=0.04, atol=0.004)


def test_a_shadow_on_the_back_darkens_the_front(scene):
    material = dict(color=(0.3, 0.3, 0.3, 1.0), diffuse_transmission=1.0, diffuse_transmission_color=COLOUR)
    open_sheet = linear_middle(scene, sheet(plain(**material), BEHIND))
    shaded = linear_middle(scene, sheet(plain(**material), BEHIND, blocker=True))
    assert shaded.mean() < 0.5 * open_sheet.mean()


def test_a_gltf_diffuse_transmission_is_read_and_bad_values_refused(tmp_path):
    from engine.assets.mesh import load_model
    from engine.core.errors import AssetError
    from tests.test_materials_from_files import write_glb

    def material(ext):
        return {"name": "leaf", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.6, 0.1, 1.0]},
                "extensions": {"KHR_materials_diffuse_transmission": ext}}
    (part,) = load_model(write_glb(tmp_path / "leaf.glb", sphere(0.5), material(
        {"diffuseTransmissionFactor": 0.7, "diffuseTransmissionColorFactor": [0.5, 1.0, 0.2]}), []))
    assert part.diffuse_transmission == pytest.approx(0.7) and part.diffuse_transmission_color == (0.5, 1.0, 0.2)
    with pytest.raises(AssetError, match=r"'leaf'.*diffuseTransmissionFactor must be a number in \[0, 1\]"):
        load_model(write_glb(tmp_path / "bad.glb", sphere(0.5), material({"diffuseTransmissionFactor": 2}), []))
    with pytest.raises(ComponentValueError, match="Material.diffuse_transmission_color"):
        Material(diffuse_transmission_color=(2.0, 0.0, 0.0))
    with pytest.raises(ComponentValueError, match="Material.diffuse_transmission"):
        Material(diffuse_transmission=-0.1)


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_sheet_in_a_mirror_and_through_a_portal_shows_the_side_that_views_eye_sees(scene, way):
    """A sheet off to the camera's right, parallel to a mirror (its front towards the camera, its
    back towards the camera's image in the mirror), a lamp before each side: seen only in the
    mirror (or through a portal), it shows its back, lit by the back's lamp and by the front's
    through it, as the frame a camera at the mirror's image eye (the eye carried through the
    portal) draws, turned left for right for the mirror (tests/test_clearcoat.py's
    assert_shown_as_from_its_eye); and the transmission is there (the opaque sheet's differs)."""
    from tests.test_clearcoat import MIRROR_TURN, SEEN, assert_shown_as_from_its_eye

    def front_lamp(world):
        world.spawn(Transform(position=SEEN + MIRROR_TURN * glm.vec3(0.3, 0.5, 1.2)),
                    PointLight(intensity=8.0, range=20.0))
    base = dict(color=(*COLOUR, 1.0), roughness=0.6, double_sided=True)
    through = dict(base, diffuse_transmission=0.6, diffuse_transmission_color=(0.3, 0.9, 0.4))
    assert_shown_as_from_its_eye(scene, through, base, way, mesh=quad(1.8, 1.8), turn=MIRROR_TURN, extra=front_lamp)
