"""Normal maps (Material.normal_map): a map of one bent normal must shade a flat surface as
a surface turned to that normal shades (the second path: real geometry), for lighting,
sky reflections and mirrors; the map's axes follow the mesh's UVs whatever the mesh's pose."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Camera, DirectionalLight, Emissive, Material, MeshRef, Mirror, Reflective, Skybox, Transform
from engine.assets.mesh import Mesh, box, quad
from engine.assets.texture_data import TextureData, checker_texture
from engine.core.errors import GLLimitError
from engine.render.gl_context import GLCapabilities
from engine.render.sky import face_directions
from tests.support import look_from

TILT = math.radians(18.0)


def tilt_map(axis: str, angle: float = TILT, size: int = 8) -> TextureData:
    """A normal map of one normal, turned by ``angle`` towards +U ("u") or +V ("v")."""
    n = np.array([math.sin(angle), 0.0, math.cos(angle)] if axis == "u" else [0.0, math.sin(angle), math.cos(angle)])
    return TextureData(np.tile(np.round((n * 0.5 + 0.5) * 255).astype(np.uint8), (size, size, 1)), name=f"tilt {axis}")


def tilted(axis: str, angle: float = TILT) -> glm.quat:
    """The local rotation that turns a quad's +Z normal as the map turns it: towards +X
    (the quad's +U) about +Y, or towards +Y (+V) about -X."""
    return glm.angleAxis(angle, glm.vec3(0, 1, 0)) if axis == "u" else glm.angleAxis(angle, glm.vec3(-1, 0, 0))


def direction_sky() -> Skybox:
    """A sky whose colour is its direction (x, y, z -> r, g, b, from 0 at -1 to 1 at +1): a
    reflection's colour says where its ray went, smoothly, in every direction."""
    return Skybox(faces=[face_directions(face, 32) * 0.5 + 0.5 for face in range(6)])


def centre_pixel(runner, point=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The mean of the 3 x 3 pixels around where ``point`` lands, after two frames (the
    second: every probe and reflection settled)."""
    runner.frame()
    rgb = runner.frame()
    col, row = runner.project(point)
    return rgb[row - 1:row + 2, col - 1:col + 2].reshape(-1, 3).astype(float).mean(axis=0)


@pytest.mark.parametrize("kind", ["lit", "chrome"])
@pytest.mark.parametrize("axis", ["u", "v"])
@pytest.mark.parametrize("pose", [0.0, 90.0, 200.0])
def test_a_map_of_one_bent_normal_shades_a_flat_quad_as_the_turned_quad(scene, kind, axis, pose):
    """``pose`` turns the quad (and its UV axes) about the view axis: the map must follow the
    UVs, not the screen."""
    base = glm.angleAxis(math.radians(pose), glm.vec3(0, 0, 1))

    def build(mapped: bool | None):
        def b(world):
            world.spawn(Transform(position=(0.0, 0.0, 2.5)), Camera(fov_y=50.0))
            world.spawn(DirectionalLight(direction=(-0.5, -0.6, -0.6), intensity=2.5))
            world.spawn(direction_sky())
            rotation = base * tilted(axis) if mapped is False else base
            parts = [Material(color=(0.7, 0.6, 0.5), roughness=0.5,
                              normal_map=tilt_map(axis) if mapped else None)]
            if kind == "chrome":
                parts = [Material(color=(1, 1, 1), metallic=1.0, roughness=0.0,
                                  normal_map=tilt_map(axis) if mapped else None), Reflective("skybox")]
            world.spawn(Transform(rotation=rotation), MeshRef(quad(1.0, 1.0)), *parts)
        return b

    colours = {}
    for mapped in (True, False, None):  # the map, the turned quad, the flat quad
        runner = scene(build(mapped), (96, 96))
        colours[mapped] = centre_pixel(runner)
        runner.close()
    np.testing.assert_allclose(colours[True], colours[False], atol=3.0)
    assert np.abs(colours[True] - colours[None]).max() > 12.0, colours  # the map does something


def mirrored_uv_quad(size: float = 1.0) -> Mesh:
    """A quad whose u runs the other way (+u along -x, +v still along +y): the UVs of a model's
    mirrored half, whose tangent frame is left-handed (glTF's tangent w of -1)."""
    flat = quad(size, size)
    uvs = flat.uvs.copy()
    uvs[:, 0] = 1.0 - uvs[:, 0]
    return Mesh(flat.positions.copy(), flat.normals.copy(), uvs, flat.indices.copy(), name="mirrored uv quad")


def sheet_colour(scene, mapped: bool | None, axis: str, *, mirrored_uvs: bool = False, from_behind: bool = False):
    """The centre of a lit quad: with the map bent towards +U or +V (``mapped``), or without
    one, turned as the map says the normal is (``mapped`` False), or flat (None).  With
    ``mirrored_uvs`` the quad's u runs along -x, so +U on it is -x: the turned quad for "u" is
    turned the other way.  ``from_behind``: a double-sided quad seen from its back (the camera
    at -z, the sun on that side), where the normal is the front's turned round (glTF's
    double-sided: the back's normal is minus the front's, bumps and all)."""
    def build(world):
        eye = -2.5 if from_behind else 2.5
        look_from(world, (0.0, 0.0, eye), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(DirectionalLight(direction=(-0.5, -0.6, 0.6 if from_behind else -0.6), intensity=2.5))
        sign = -1.0 if (mirrored_uvs and axis == "u") else 1.0
        rotation = tilted(axis, sign * TILT) if mapped is False else glm.quat()
        world.spawn(Transform(rotation=rotation), MeshRef(mirrored_uv_quad() if mirrored_uvs else quad(1.0, 1.0)),
                    Material(color=(0.7, 0.6, 0.5), roughness=0.5, double_sided=from_behind,
                             normal_map=tilt_map(axis) if mapped else None))
    runner = scene(build, (48, 48))
    colour = centre_pixel(runner)
    runner.close()
    return colour


@pytest.mark.parametrize("axis", ["u", "v"])
@pytest.mark.parametrize("case", ["mirrored_uvs", "from_behind"])
def test_a_bent_normal_follows_mirrored_uvs_and_turns_round_on_a_double_sided_back(scene, axis, case):
    """On UVs whose u runs backwards the map's red still leans towards +U (-x there) and its
    green towards +V (the frame is the UVs' gradients, not n x t); seen from behind, a
    double-sided quad's bent normal is minus the front's, as the turned quad's is."""
    colours = {mapped: sheet_colour(scene, mapped, axis, **{case: True}) for mapped in (True, False, None)}
    np.testing.assert_allclose(colours[True], colours[False], atol=3.0)
    assert np.abs(colours[True] - colours[None]).max() > 12.0, colours  # the map does something


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_normal_mapped_ball_in_a_mirror_and_through_a_portal_is_shaded_from_that_views_eye(scene, way):
    """A ball whose map leans every normal 30 degrees towards +U, seen only in a mirror (or
    through a portal): the frame a camera at the mirror's image eye draws of it (the eye carried
    through the portal), turned left for right for the mirror (tests/test_clearcoat.py's
    assert_shown_as_from_its_eye).  A mirror's view draws the world turned, its screen's
    frame left-handed: the UVs' gradients must come out the same there."""
    from tests.test_clearcoat import assert_shown_as_from_its_eye
    base = dict(color=(0.6, 0.5, 0.4, 1.0), roughness=0.35)
    assert_shown_as_from_its_eye(scene, dict(base, normal_map=tilt_map("u", math.radians(30.0))), base, way)


def test_normal_scale_zero_is_flat_and_scales_the_slope(scene):
    def build(scale: float | None, rotation: glm.quat | None = None):
        def b(world):
            world.spawn(Transform(position=(0.0, 0.0, 2.5)), Camera(fov_y=50.0))
            world.spawn(DirectionalLight(direction=(-0.8, 0.0, -0.6), intensity=2.5))
            world.spawn(Transform(rotation=rotation or glm.quat()), MeshRef(quad(1.0, 1.0)),
                        Material(color=(0.7, 0.7, 0.7), roughness=1.0,
                                 normal_map=tilt_map("u", math.radians(20.0)) if scale is not None else None,
                                 normal_scale=scale or 0.0))
        return b

    def colour(*args):
        runner = scene(build(*args), (64, 64))
        c = centre_pixel(runner)
        runner.close()
        return c

    np.testing.assert_allclose(colour(0.0), colour(None), atol=1.0)
    # scale 2 doubles the tangent part: the normal is (2 sin 20, 0, cos 20), normalised.
    turned = math.atan2(2.0 * math.sin(math.radians(20.0)), math.cos(math.radians(20.0)))
    np.testing.assert_allclose(colour(2.0), colour(None, glm.angleAxis(turned, glm.vec3(0, 1, 0))), atol=3.0)


def gradient_wall(world) -> None:
    """A far emissive wall behind the camera whose colour changes along x and y, lit by nothing:
    what a mirror shows of it says where its reflected ray went."""
    x = np.linspace(0.0, 1.0, 256)
    pixels = np.zeros((256, 256, 3), np.uint8)
    pixels[..., 0] = np.round(255 * x)[None, :]
    pixels[..., 1] = np.round(255 * x)[::-1, None]
    pixels[..., 2] = 40
    world.spawn(Transform(position=(0.0, 0.0, 60.0), rotation=glm.angleAxis(math.pi, glm.vec3(0, 1, 0))),
                MeshRef(quad(80.0, 80.0)), Material(color=(1.0, 1.0, 1.0), texture=TextureData(pixels, "wall")),
                Emissive(1.0))


@pytest.mark.parametrize("axis", ["u", "v"])
@pytest.mark.parametrize("roughness", [0.0, 0.15])
def test_a_mirror_with_a_map_of_one_bent_normal_shows_what_the_turned_mirror_shows(scene, axis, roughness):
    """The bent lookup is exact for distant things: a wall 60 units away, seen in a mirror 4
    units from the eye, within a few levels of the turned mirror's image.  (A lookup that
    would leave the mirror's own pixels keeps the flat one: the tilt is kept small.)"""
    angle = math.radians(4.0)

    def build(mapped: bool | None):
        def b(world):
            world.spawn(Transform(position=(0.0, 0.0, 4.0)), Camera(fov_y=50.0))
            gradient_wall(world)
            rotation = tilted(axis, angle) if mapped is False else glm.quat()
            world.spawn(Transform(rotation=rotation), MeshRef(quad(6.0, 6.0)),
                        Material(color=(0.05, 0.05, 0.05), normal_map=tilt_map(axis, angle) if mapped else None),
                        Mirror(roughness=roughness))
        return b

    colours = {}
    for mapped in (True, False, None):
        runner = scene(build(mapped), (120, 120))
        colours[mapped] = centre_pixel(runner)
        runner.close()
    np.testing.assert_allclose(colours[True], colours[False], atol=8.0)
    assert np.abs(colours[True] - colours[None]).max() > 25.0, colours


def test_a_mirror_normal_map_needs_uvs_that_vary_linearly_over_the_mirror(scene):
    """Refused when given: at spawn, when the map is set on a mirror, when the mesh changes."""
    flat = quad(2.0, 2.0)
    uvs = flat.uvs.copy()
    uvs[0] += (0.3, 0.0)  # one corner's UV off the plane map
    warped = Mesh(flat.positions, flat.normals, uvs, flat.indices, name="warped quad")
    refusal = r"Material.normal_map needs UVs that vary linearly.*'warped quad'"
    ents = {}

    def build(world):
        world.spawn(Transform(position=(0.0, 0.0, 4.0)), Camera())
        with pytest.raises(ValueError, match=refusal):
            world.spawn(Transform(), MeshRef(warped), Material(normal_map=tilt_map("u")), Mirror())
        ents["plain"] = world.spawn(Transform(), MeshRef(warped), Material(), Mirror())
        ents["bumpy"] = world.spawn(Transform(), MeshRef(quad(2.0, 2.0)), Material(normal_map=tilt_map("u")),
                                    Mirror())

    runner = scene(build, (32, 32))
    runner.frame()
    with pytest.raises(ValueError, match=refusal):
        runner.world.get(ents["plain"], Material).normal_map = tilt_map("u")
    with pytest.raises(ValueError, match=refusal):
        runner.world.get(ents["bumpy"], MeshRef).mesh = warped
    runner.frame()  # nothing half-set: both still draw


def test_normal_maps_are_shared_uploaded_linear_and_released(scene):
    image = checker_texture(16, 2)

    def build(world):
        world.spawn(Transform(position=(0.0, 0.0, 5.0)), Camera())

    runner = scene(build, (32, 32))
    renderer = runner.engine.renderer
    crate = box()
    for cycle in range(2):
        spawned = [runner.world.spawn(Transform(position=(i, 0, 0)), MeshRef(crate),
                                      Material(texture=image, normal_map=image if i % 2 else None))
                   for i in range(4)]
        runner.frame()
        # The image as albedo (sRGB) and as a normal map (linear) is two textures, each shared.
        counts = renderer.resource_counts()
        assert (counts["textures"], counts["batches"]) == (2, 2), cycle
        normal = renderer.normal_map_texture(image)
        assert normal is not None and normal.dtype == "f1" and normal.components == 4
        # Trilinear on a software rasteriser (8x anisotropic cost llvmpipe a third of a frame).
        assert normal.anisotropy == renderer.normal_map_anisotropy
        assert renderer.normal_map_anisotropy == (renderer.texture_anisotropy
                                                  if renderer.caps.filters_anisotropically else 1.0)
        for e in spawned:
            runner.world.delete_entity(e)
        runner.frame()
        counts = renderer.resource_counts()
        assert (counts["textures"], counts["batches"]) == (0, 0), cycle
        assert renderer.normal_map_texture(image) is None


def test_a_normal_map_over_the_gl_limit_is_named_with_its_entity_and_field(scene, ctx):
    limit = GLCapabilities.read(ctx).max_texture_size
    wide = TextureData(np.full((1, limit + 1, 4), 128, np.uint8), name="bumps.png")
    ents = {}

    def build(world):
        world.spawn(Transform(position=(0, 0, 3)), Camera())
        ents["crate"] = world.spawn(Transform(), MeshRef(box()), Material(normal_map=wide))

    runner = scene(build, (32, 32))
    with pytest.raises(GLLimitError, match=rf"entity {ents['crate']}: Material.normal_map: texture 'bumps.png' "
                                           rf"is {limit + 1}x1"):
        runner.frame()
    assert runner.engine.renderer.resource_counts()["textures"] == 0


@pytest.mark.parametrize("value, message", [(-0.5, "normal_scale"), (float("nan"), "normal_scale"),
                                            (100.0, "normal_scale")])
def test_a_bad_normal_scale_is_refused_naming_the_field(value, message):
    with pytest.raises(ValueError, match=message):
        Material(normal_scale=value)
    with pytest.raises(ValueError, match="Material.normal_map must be an engine.assets.texture_data.TextureData"):
        Material(normal_map=np.zeros((4, 4, 3), np.uint8))
