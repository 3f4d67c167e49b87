"""Baked lightmaps (``Material.lightmap``, ``lightmap_intensity``): the light from all round
read from an image in place of the sky's, a probe's or a volume's, each texel the colour a
white matte surface shows (Lambert's albedo / pi of pi x its colour).  The floor's HDR pixels
against the image sampled in numpy where each pixel's ray meets the floor (the plane's UVs,
GL's bilinear filter of sRGB-decoded texels), the lights' own light added on top, the second
UV set, and the limits; bakes: an open floor, a floor by a glowing wall, and a closed room
baked for several bounces against the furnace test's series."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import Mesh, box, plane
from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitError
from tests.support import look_from, srgb_to_linear
from tests.test_generated_sky import SIZE, _read

ALBEDO = np.array([0.8, 0.6, 0.4])
HALF = 2.0   # the floor's half side (a 4 m plane, its UVs 0..1 across)


def gradient_image(size: int = 32) -> TextureData:
    """Red rising to the right, green rising to the top, a little blue: smooth, so a texel's
    place matters little and the filter's rounding less."""
    pixels = np.zeros((size, size, 4), np.uint8)
    ramp = np.linspace(40, 230, size)
    pixels[..., 0] = ramp[None, :]
    pixels[..., 1] = ramp[::-1, None]   # (row 0 is the image's top)
    pixels[..., 2] = 60
    pixels[..., 3] = 255
    return TextureData(pixels, name="gradient lightmap")


def sample(image: TextureData, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear RGB of ``image`` at UVs (v = 0 its bottom row), bilinear between texel centres
    of the sRGB-decoded texels, clamped at the edges (GL's LINEAR on the finest level)."""
    texels = srgb_to_linear(image.as_8_bits()[::-1, :, :3])   # (rows bottom-first, as GL holds them)
    h, w = texels.shape[:2]
    x = np.clip(u * w - 0.5, 0.0, w - 1.0)
    y = np.clip(v * h - 0.5, 0.0, h - 1.0)
    x0, y0 = np.minimum(x.astype(int), w - 2), np.minimum(y.astype(int), h - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    top = texels[y0, x0] * (1 - fx) + texels[y0, x0 + 1] * fx
    bottom = texels[y0 + 1, x0] * (1 - fx) + texels[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def floor_frame(scene, material: Material, mesh: Mesh | None = None, sky: Skybox | None = None,
                sun: DirectionalLight | None = None):
    """The floor seen from 4.5 m straight above: level 0's HDR colour, the floor's UVs under
    each pixel and the mask of pixels well inside it; and the runner."""
    def build(world):
        look_from(world, (0.0, 4.5, 0.0), (0.0, 0.0, -0.001), fov=50.0)
        world.spawn(sky or Skybox())
        if sun is not None:
            world.spawn(sun)
        world.spawn(Transform(), MeshRef(mesh or plane(2 * HALF, 2 * HALF)), material)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    eye = np.array(runner.engine.main_view.eye, np.float64)
    hit = eye + rays * (-eye[1] / rays[..., 1:2])
    u, v = (hit[..., 0] + HALF) / (2 * HALF), (HALF - hit[..., 2]) / (2 * HALF)
    inside = (np.abs(hit[..., 0]) < HALF - 0.15) & (np.abs(hit[..., 2]) < HALF - 0.15)
    return colour, u, v, inside, runner


def matte(**fields) -> Material:
    return Material(color=(*ALBEDO, 1.0), roughness=1.0, environment_reflection=0.0, **fields)


def test_the_floor_shows_its_albedo_times_the_lightmap(scene):
    """No light but the sky's: every pixel is albedo x the image's colour there x the
    intensity (within 2%, and 0.004 for the half floats), whatever the sky is."""
    image = gradient_image()
    colour, u, v, inside, _ = floor_frame(scene, matte(lightmap=image, lightmap_intensity=1.5))
    assert inside.sum() > 5000
    want = ALBEDO * sample(image, u, v) * 1.5
    np.testing.assert_allclose(colour[inside], want[inside], rtol=0.02, atol=0.004)
    bright = Skybox(zenith=(1.0, 1.0, 2.0), horizon=(2.0, 2.0, 2.0), ground=(0.5, 0.5, 0.5))
    again, *_ = floor_frame(scene, matte(lightmap=image, lightmap_intensity=1.5), sky=bright)
    np.testing.assert_allclose(again[inside], colour[inside], atol=1e-3)   # the sky's light is not added
    plain, *_ = floor_frame(scene, matte(), sky=bright)
    assert np.abs(plain[inside] - colour[inside]).mean() > 0.1                 # (without it, it is)


def test_the_lights_own_light_adds_to_the_baked_light(scene):
    """A sun over the lightmapped floor: the floor is the lightmap's light plus the sun's, the
    sun's measured on a plain floor under a black sky (no light from all round at all)."""
    image = gradient_image()
    sun = dict(direction=(0.3, -1.0, 0.2), intensity=2.0, shadows=False)
    black = Skybox(faces=np.zeros((6, 4, 4, 3), np.float32))
    lit, u, v, inside, _ = floor_frame(scene, matte(lightmap=image), sun=DirectionalLight(**sun))
    direct, *_ = floor_frame(scene, matte(), sky=black, sun=DirectionalLight(**sun))
    assert direct[inside].min() > 0.2
    np.testing.assert_allclose(lit[inside], direct[inside] + ALBEDO * sample(image, u, v)[inside],
                               rtol=0.02, atol=0.004)


def test_a_lightmap_reads_the_second_uv_set_when_told(scene):
    """The same floor with a second UV set turned half round (u, v -> 1 - u, 1 - v) and
    ``second_uv_maps=("lightmap",)``: the image turned half round on it; without the switch the
    first set's."""
    image = gradient_image()
    base = plane(2 * HALF, 2 * HALF)
    turned = Mesh(base.positions, base.normals, base.uvs, base.indices, name="turned",
                  second_uvs=1.0 - np.asarray(base.uvs))
    colour, u, v, inside, _ = floor_frame(scene, matte(lightmap=image, second_uv_maps=("lightmap",)), mesh=turned)
    np.testing.assert_allclose(colour[inside], (ALBEDO * sample(image, 1.0 - u, 1.0 - v))[inside],
                               rtol=0.02, atol=0.004)
    first, *_ = floor_frame(scene, matte(lightmap=image), mesh=turned)
    np.testing.assert_allclose(first[inside], (ALBEDO * sample(image, u, v))[inside], rtol=0.02, atol=0.004)


def test_the_lightmap_goes_with_its_entity(scene):
    image = gradient_image()
    _, _, _, _, runner = floor_frame(scene, matte(lightmap=image))
    renderer = runner.engine.renderer
    textures = renderer.resource_counts()["textures"]
    world = runner.engine.world
    world.delete_entity(next(entity for entity, _ in world.query_one(Material)))
    runner.frame()
    assert renderer.resource_counts()["textures"] == textures - 1


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_mirrors_show_the_lightmapped_floor_as_the_image_says_where_their_rays_meet_it(scene, path):
    """Two mirrors overhead facing down, the camera under them looking up: every pixel of the
    floor in them (their views: a reflection level's scene pass) is albedo x the image
    where the pixel's ray, reflected at y = 3, meets the floor, x the intensity, as the main
    view's floor is, and the sky's light is not added (the same under a brighter sky; a floor
    without the lightmap shows that sky's light).  Both of the reflection levels' paths: each
    view its own draws, and the views in one draw (``BATCHED_VIEWS``)."""
    from components import Mirror
    from engine.assets.mesh import quad

    image = gradient_image()

    def frame(material: Material, sky: Skybox | None = None):
        def build(world):
            look_from(world, (0.0, 1.0, 0.0), (0.0, 3.0, -0.001), fov=50.0)
            world.spawn(sky or Skybox())
            world.spawn(Transform(), MeshRef(plane(2 * HALF, 2 * HALF)), material)
            for x in (-3.0, 3.0):   # two mirrors side by side: one level of two views
                world.spawn(Transform(position=(x, 3.0, 0.0), rotation=glm.angleAxis(glm.pi() / 2, glm.vec3(1, 0, 0))),
                            MeshRef(quad(6.0, 12.0)), Material(), Mirror())

        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.frame()
        colour, rays = _read(runner)
        return colour, rays, runner

    colour, rays, runner = frame(matte(lightmap=image, lightmap_intensity=1.5))
    assert runner.stats.reflection_views == 2
    eye = np.array(runner.engine.main_view.eye, np.float64)
    assert (rays[..., 1] > 0.3).all()   # (every pixel looks up at the mirror)
    up, down = (3.0 - eye[1]) / rays[..., 1], 3.0 / rays[..., 1]   # to the mirror, then down to the floor
    hit = eye + rays * (up + down)[..., None]
    u, v = (hit[..., 0] + HALF) / (2 * HALF), (HALF - hit[..., 2]) / (2 * HALF)
    seam = np.abs(eye[0] + rays[..., 0] * up) < 0.05   # (where the two mirrors meet)
    inside = (np.abs(hit[..., 0]) < HALF - 0.15) & (np.abs(hit[..., 2]) < HALF - 0.15) & ~seam
    assert inside.sum() > 3000
    want = ALBEDO * sample(image, u, v) * 1.5
    np.testing.assert_allclose(colour[inside], want[inside], rtol=0.02, atol=0.004)
    bright = Skybox(zenith=(1.0, 1.0, 2.0), horizon=(2.0, 2.0, 2.0), ground=(0.5, 0.5, 0.5))
    again, *_ = frame(matte(lightmap=image, lightmap_intensity=1.5), sky=bright)
    np.testing.assert_allclose(again[inside], colour[inside], atol=1e-3)   # the sky's light is not added
    plain, *_ = frame(matte(), sky=bright)
    assert np.abs(plain[inside] - colour[inside]).mean() > 0.1              # (without it, it is)



@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_a_portal_shows_the_lightmapped_floor_as_the_image_says_where_its_carried_rays_meet_it(scene, scale):
    """A portal pair facing down, A far off over the camera, B 3 m over the lightmapped floor
    (``scale``: B's Transform's): every pixel of the floor seen through A (its view: a
    reflection level's scene pass) is albedo x the image x the intensity where the pixel's
    ray, carried by the pair's transform (float64, from the Transforms), meets the floor,
    unscaled by the pair's scale; the floor's entity is what those pixels show."""
    from engine.assets.portals import spawn_portal_pair

    image = gradient_image()
    down = glm.angleAxis(glm.pi() / 2, glm.vec3(1, 0, 0))   # a quad's front (+Z) turned to -Y
    ents = {}

    def build(world):
        look_from(world, (20.0, 1.2, 0.0), (20.0, 3.0, -0.001), fov=60.0)
        world.spawn(Skybox())
        ents["floor"] = world.spawn(Transform(), MeshRef(plane(2 * HALF, 2 * HALF)),
                                    matte(lightmap=image, lightmap_intensity=1.5))
        ents["a"], ents["b"] = spawn_portal_pair(world, (20.0, 3.0, 0.0), down, (0.0, 3.0, 0.0), down)
        world.get(ents["b"], Transform).scale = glm.vec3(scale)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    assert runner.stats.reflection_views == 1
    on_a = runner.engine.renderer.targets.read_surface_ids() == ents["a"]
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = b_world @ turn @ np.linalg.inv(a_world)
    eye = carry[:3, :3] @ np.array(runner.engine.main_view.eye, np.float64) + carry[:3, 3]
    ways = rays @ carry[:3, :3].T
    hit = eye + ways * (-eye[1] / np.where(ways[..., 1] < -1e-6, ways[..., 1], -1.0))[..., None]
    u, v = (hit[..., 0] + HALF) / (2 * HALF), (HALF - hit[..., 2]) / (2 * HALF)
    inside = on_a & (ways[..., 1] < -0.1) & (np.abs(hit[..., 0]) < HALF - 0.15) & (np.abs(hit[..., 2]) < HALF - 0.15)
    edge = np.zeros_like(on_a)   # (a pixel beside the portal's outline: its composite's edge)
    for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        edge |= ~np.roll(on_a, shift, axis=(0, 1))
    inside &= ~edge
    assert inside.sum() > 1500
    assert (runner.ids()[inside] == ents["floor"]).all()
    want = ALBEDO * sample(image, u, v) * 1.5
    np.testing.assert_allclose(colour[inside], want[inside], rtol=0.02, atol=0.004)


def test_a_probes_faces_show_the_lightmapped_floor_as_the_image_says_where_their_texels_look(scene, ctx):
    """A reflection probe 0.6 m over the lightmapped floor: each texel of its capture (level 0
    of every face, read back) that sees the floor is albedo x the image x the intensity where
    the texel centre's way from the probe meets the floor (``face_directions``), unscaled, as
    the main view's floor is: the face looking down whole, the side faces' lower rows (ways
    steeper than 33 degrees: flatter ones read the lightmap's coarser mips, which the
    finest-level ``sample`` is not)."""
    from components import ReflectionProbe
    from engine.core.cube_faces import face_directions
    from engine.render.bindings import SCRATCH_UNIT
    from engine.render.raw_gl import read_cube_level

    image = gradient_image()
    n, centre = 32, np.array([0.3, 0.6, -0.2])

    def build(world):
        look_from(world, (0.0, 4.5, 0.0), (0.0, 0.0, -0.001), fov=50.0)
        world.spawn(Skybox())
        world.spawn(Transform(), MeshRef(plane(2 * HALF, 2 * HALF)), matte(lightmap=image, lightmap_intensity=1.5))
        world.spawn(Transform(position=tuple(centre)), ReflectionProbe(resolution=n, far=20.0, refresh="every_frame"))

    runner = scene(build, SIZE)
    for _ in range(2):
        runner.frame()
    (texture,) = [cube.texture for cube in runner.engine.renderer.probes.cubes.values()]
    checked = 0
    for face in range(6):
        got = read_cube_level(ctx, texture, face, 0, SCRATCH_UNIT)[..., :3].astype(np.float64)
        ways = face_directions(face, n)
        hit = centre + ways * (-centre[1] / np.where(ways[..., 1] < -1e-6, ways[..., 1], -1.0))[..., None]
        u, v = (hit[..., 0] + HALF) / (2 * HALF), (HALF - hit[..., 2]) / (2 * HALF)
        inside = (ways[..., 1] < -0.55) & (np.abs(hit[..., 0]) < HALF - 0.15) & (np.abs(hit[..., 2]) < HALF - 0.15)
        want = ALBEDO * sample(image, u, v) * 1.5
        np.testing.assert_allclose(got[inside], want[inside], rtol=0.02, atol=0.004, err_msg=f"face {face}")
        checked += inside.sum()
    assert checked > n * n + 400


def test_an_end_image_shows_the_lightmapped_floor_where_last_frames_reprojected_ray_meets_it(scene):
    """Two mirrors facing across a lightmapped floor (z = -1 and +1, depth 2): the third
    image of the one ahead (its plane's copy at z = -5, unfolding the reflections) is cut,
    an end image (``engine/render/end_images.py``): a pixel whose ray meets that copy at
    (x, y) shows what last frame's picture showed at (x, y, -1) on the mirror itself.  Each
    such pixel whose ray from the eye to (x, y, -1) (float64, the reflections unfolded:
    z -> -2 - z past the first plane, z + 4 past the second) meets the floor is albedo x the
    image there x the intensity, within 2% and 0.004 (last frame's picture read between its
    pixels); not on the first frame (no image yet: the fallback), and the sky's light is not
    added (the same under a brighter sky; a floor without the lightmap shows it)."""
    from components import Mirror
    from engine.assets.mesh import quad

    image, wide, room = gradient_image(), 3.0, 1.0   # the floor 6 m across (x), 2 m between the mirrors (z)

    def frames(material: Material, sky: Skybox | None = None):
        def build(world):
            look_from(world, (0.3, 0.8, 0.9), (0.0, 0.5, -5.0), fov=40.0)
            world.spawn(sky or Skybox())
            world.spawn(Transform(), MeshRef(plane(2 * wide, 2 * room)), material)
            for z, turn in ((-room, 0.0), (room, glm.pi())):
                world.spawn(Transform(position=(0.0, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                            MeshRef(quad(2 * wide, 3.0)), Material(), Mirror(max_depth=2, end_image=True))

        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        shown = []
        for _ in range(2):
            runner.frame()
            shown.append(_read(runner)[0])
        assert runner.stats.reflection_end_views == 1
        return shown, runner

    (first, colour), runner = frames(matte(lightmap=image, lightmap_intensity=1.5))
    _, rays = _read(runner)
    eye = np.array(runner.engine.main_view.eye, np.float64)
    margin = 0.15
    ahead = np.where(rays[..., 2] < -0.05, rays[..., 2], -1.0)
    cut = rays[..., 2] < -0.05
    for k in range(3):   # the ray crosses the mirror ahead, the one behind and the one ahead again
        at = eye + rays * ((-room - 2 * room * k - eye[2]) / ahead)[..., None]
        cut &= (np.abs(at[..., 0]) < wide - margin) & (at[..., 1] > margin) & (at[..., 1] < 3.0 - margin)
    x, y = at[..., 0], at[..., 1]
    on_mirror = np.stack([x, y, np.full_like(x, -room), np.ones_like(x)], -1)
    view_proj = np.array(glm.dmat4(runner.engine.main_view.view_proj).to_list(), np.float64).T
    clip = on_mirror @ view_proj.T
    cut &= (np.abs(clip[..., :2] / clip[..., 3:]) < 1 - 4.0 / np.array(SIZE)).all(axis=-1)   # held by last frame's
    way = on_mirror[..., :3] - eye
    cut &= way[..., 1] < -0.05
    hit = eye + way * (-eye[1] / np.where(way[..., 1] < -0.05, way[..., 1], -1.0))[..., None]
    beyond = -room - hit[..., 2]   # how far past the mirror ahead, unfolded
    cut &= (beyond > margin) & (beyond < 4 * room - margin) & (np.abs(beyond - 2 * room) > margin)
    cut &= np.abs(hit[..., 0]) < wide - margin
    z = np.where(beyond < 2 * room, -2 * room - hit[..., 2], hit[..., 2] + 4 * room)   # folded back into the room
    u, v = (hit[..., 0] + wide) / (2 * wide), (room - z) / (2 * room)
    assert cut.sum() > 300
    want = ALBEDO * sample(image, u, v) * 1.5
    np.testing.assert_allclose(colour[cut], want[cut], rtol=0.02, atol=0.004)
    assert np.abs(first[cut] - want[cut]).max(axis=-1).mean() > 0.1   # (the first frame's fallback is not it)
    bright = Skybox(zenith=(1.0, 1.0, 2.0), horizon=(2.0, 2.0, 2.0), ground=(0.5, 0.5, 0.5))
    (_, again), _ = frames(matte(lightmap=image, lightmap_intensity=1.5), sky=bright)
    np.testing.assert_allclose(again[cut], colour[cut], atol=1e-3)   # the sky's light is not added
    (_, plain), _ = frames(matte(), sky=bright)
    assert np.abs(plain[cut] - colour[cut]).mean() > 0.1              # (without it, it is)


@pytest.mark.parametrize("field, value", [("lightmap_intensity", -1.0), ("lightmap_intensity", float("nan")),
                                          ("lightmap_intensity", 1e5), ("lightmap", "lightmap.png")])
def test_bad_lightmap_values_are_refused_when_given(field, value):
    with pytest.raises(ComponentValueError, match=f"Material.{field}"):
        Material(**{field: value})


def test_a_lightmap_with_an_occlusion_map_on_a_16_unit_context_is_refused_naming_the_entity(scene):
    """With its own occlusion map a lightmapped batch reads 17 samplers: a context with 16
    (macOS's GL 4.1) refuses it when it is drawn, saying what to do; packed in the
    metallic-roughness map's red it fits."""
    image = gradient_image()
    occlusion = TextureData(np.full((4, 4, 4), 255, np.uint8), name="occlusion")

    def build(world):
        look_from(world, (0.0, 4.5, 0.0), (0.0, 0.0, -0.001))
        world.spawn(Transform(), MeshRef(plane(4.0, 4.0)), matte(lightmap=image, occlusion_map=occlusion))

    runner = scene(build, SIZE)
    renderer = runner.engine.renderer
    renderer.caps = dataclasses.replace(renderer.caps, max_texture_image_units=16)
    with pytest.raises(GLLimitError, match=r"entity \d+.*lightmap and an occlusion map needs 17 texture units"):
        runner.frame()
    packed = scene(lambda world: (look_from(world, (0.0, 4.5, 0.0), (0.0, 0.0, -0.001)), world.spawn(
        Transform(), MeshRef(plane(4.0, 4.0)), matte(lightmap=image, metallic_roughness_map=occlusion,
                                                      occlusion_map=occlusion))), SIZE)
    packed.engine.renderer.caps = dataclasses.replace(packed.engine.renderer.caps, max_texture_image_units=16)
    packed.frame()


def test_a_level_file_gives_a_lightmap(tmp_path):
    from engine.assets.level_read import load_level
    from engine.core.world import World

    level = tmp_path / "baked.toml"
    level.write_text('[level]\nname = "baked"\n[[entity]]\nname = "floor"\nTransform = {}\n'
                     'MeshRef = { mesh = { plane = [4.0, 4.0] } }\n'
                     'Material = { lightmap = { checker = [8, 2] }, lightmap_intensity = 2.0 }\n')
    world = World()
    load_level(level).spawn(world)
    material = world.query_one(Material)[0][1]
    assert isinstance(material.lightmap, TextureData) and material.lightmap_intensity == 2.0
    assert glm.vec4(material.color) == glm.vec4(0.8, 0.8, 0.8, 1.0)


# -- baking one (engine/render/lightmap_bake.py) ---------------------------------------------------
def _bake_world(wall: bool):
    """A 6 m floor under the default generated sky (no light of its own but the sky's), and
    (``wall``) a tall red wall along its -X edge, lit by a sun above it."""
    from components import Emissive

    def build(world):
        look_from(world, (0.0, 6.0, 6.0), (0.0, 0.0, 0.0))
        world.spawn(Skybox())
        floor = world.spawn(Transform(), MeshRef(plane(6.0, 6.0)), matte())
        world.resources["floor"] = floor
        if wall:
            world.spawn(Transform(position=(-3.2, 2.0, 0.0)), MeshRef(box((0.4, 4.0, 6.0))),
                        Material(color=(0.9, 0.1, 0.1), roughness=1.0, environment_reflection=0.0),
                        Emissive(power=1.5))
    return build


def test_a_baked_open_floor_holds_the_skys_light(scene):
    """Under an open sky each texel is the sky's irradiance on an upward face over pi (the
    sky's spherical harmonics in closed form: ``ambient_sh``), within 4%; and the floor lit by
    its bake shows what the sky's light showed it (within 3%)."""
    from engine.render.irradiance import evaluate_sh
    from engine.render.lightmap_bake import bake_lightmap
    from systems.prepare_system import ambient_sh

    runner = scene(_bake_world(False), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    floor = runner.world.resources["floor"]
    image, intensity = bake_lightmap(runner.engine, floor, size=8, resolution=16)
    want = evaluate_sh(ambient_sh(runner.world), np.array([0.0, 1.0, 0.0])) / np.pi
    baked = srgb_to_linear(image.as_8_bits()[..., :3]) * intensity
    np.testing.assert_allclose(baked.reshape(-1, 3), np.tile(want, (64, 1)), rtol=0.04)
    before = _read(runner)[0]
    runner.world.get(floor, Material).lightmap = image
    runner.world.get(floor, Material).lightmap_intensity = intensity
    runner.frame()
    after = _read(runner)[0]
    floor_pixels = runner.ids() == floor
    np.testing.assert_allclose(after[floor_pixels].mean(axis=0), before[floor_pixels].mean(axis=0), rtol=0.03)


def test_a_bake_beside_a_glowing_red_wall_is_darker_and_redder_near_it(scene):
    """The wall hides half the sky from the floor at its foot and glows red on it: the texels
    by the wall are darker in blue and redder than those on the far side."""
    from engine.render.lightmap_bake import bake_lightmap

    runner = scene(_bake_world(True), SIZE)
    runner.frame()
    image, intensity = bake_lightmap(runner.engine, runner.world.resources["floor"], size=8, resolution=16)
    baked = srgb_to_linear(image.as_8_bits()[..., :3]) * intensity
    near, far = baked[:, 0], baked[:, -1]   # columns: u along +X (the wall at -X)
    assert (near[:, 2] < 0.8 * far[:, 2]).all()
    assert (near[:, 0] / near[:, 2] > 2.0 * far[:, 0] / far[:, 2]).all()
    # The set the material reads its lightmap on: a second set turned half round, named for
    # the lightmap, turns the bake with it (the wall's side on the right).
    world = runner.world
    floor = world.resources["floor"]
    base = world.get(floor, MeshRef).mesh
    world.get(floor, MeshRef).mesh = Mesh(base.positions, base.normals, base.uvs, base.indices, name="turned",
                                          second_uvs=1.0 - np.asarray(base.uvs))
    world.get(floor, Material).second_uv_maps = ("lightmap",)
    runner.frame()
    turned, turned_intensity = bake_lightmap(runner.engine, floor, size=8, resolution=16)
    turned = srgb_to_linear(turned.as_8_bits()[..., :3]) * turned_intensity
    np.testing.assert_allclose(turned, baked[::-1, ::-1], rtol=0.05, atol=0.003)


def test_bad_bakes_are_refused(scene):
    from engine.core.errors import AssetError
    from engine.render.lightmap_bake import bake_lightmap

    runner = scene(_bake_world(False), SIZE)
    runner.frame()
    floor = runner.world.resources["floor"]
    for kwargs, words in ((dict(size=2), "size"), (dict(resolution=1000), "resolution"),
                          (dict(near=0.0), "near and far")):
        with pytest.raises(AssetError, match=words):
            bake_lightmap(runner.engine, floor, **kwargs)
    with pytest.raises(AssetError, match="no MeshRef"):
        bake_lightmap(runner.engine, runner.world.spawn(Transform()))
    from components import Morph

    base = plane(2.0, 2.0)
    morphed = Mesh(base.positions, base.normals, base.uvs, base.indices, name="dented",
                    morph_positions=np.zeros((1, 4, 3)))
    posed = runner.world.spawn(Transform(), MeshRef(morphed), matte(), Morph(weights=(0.5,)))
    with pytest.raises(AssetError, match="is posed"):
        bake_lightmap(runner.engine, posed)
    assert runner.engine.renderer.resource_counts()["probe_cubes"] == 0


def _furnace(albedo: float):
    """A closed 2 m room of six inward-facing walls, each matte grey ``albedo`` and glowing
    (``Emissive``), no light and a black sky; the camera inside."""
    from components import Emissive, look_rotation

    def build(world):
        look_from(world, (0.0, 0.0, 0.5), (0.0, 0.0, -1.0), fov=60.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        walls = []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                out = np.zeros(3)
                out[axis] = sign
                walls.append(world.spawn(Transform(position=tuple(out), rotation=look_rotation(glm.vec3(*out))),
                                         MeshRef(_quad(2.0)),
                                         Material(color=(albedo, albedo, albedo, 1.0), roughness=1.0, reflectance=0.0,
                                                  environment_reflection=0.0),
                                         Emissive(power=0.5)))
        world.resources["walls"] = walls
    return build


def _quad(side: float) -> Mesh:
    from engine.assets.mesh import quad

    return quad(side, side)


def test_a_closed_room_baked_for_n_bounces_holds_the_furnace_series(scene):
    """Inside a closed room every wall sees only walls: round 1's lightmap is the walls' glow
    L, and each round after adds a times the last, L (1 + a + ... + a^(n-1)) (a the albedo:
    the furnace test's series).  Every texel of every wall, 1, 2 and 3 bounces, within 1%."""
    from engine.render.lightmap_bake import bake_lightmaps

    albedo = 0.5
    runner = scene(_furnace(albedo), (32, 32))
    runner.frame()
    walls = runner.world.resources["walls"]
    light = {}
    for bounces in (1, 2, 3):
        baked = bake_lightmaps(runner.engine, walls, bounces=bounces, size=4, resolution=8)
        light[bounces] = np.stack([srgb_to_linear(image.as_8_bits()[..., :3]) * intensity
                                   for image, intensity in baked.values()])
        for entity, (image, intensity) in baked.items():   # (each put on its wall)
            material = runner.world.get(entity, Material)
            assert material.lightmap is image and material.lightmap_intensity == pytest.approx(intensity)
    glow = light[1].mean()
    assert glow > 0.05 and np.abs(light[1] - glow).max() < 0.03 * glow   # (the same all round)
    for bounces in (2, 3):
        series = sum(albedo ** k for k in range(bounces))
        np.testing.assert_allclose(light[bounces], glow * series, rtol=0.01)


def test_bad_bounces_are_refused(scene):
    from engine.core.errors import AssetError
    from engine.render.lightmap_bake import MAX_BOUNCES, bake_lightmaps

    runner = scene(_furnace(0.5), (16, 16))
    runner.frame()
    walls = runner.world.resources["walls"]
    for bad in (0, MAX_BOUNCES + 1, 1.5, True):
        with pytest.raises(AssetError, match="bounces must be a whole number"):
            bake_lightmaps(runner.engine, walls, bounces=bad)
    with pytest.raises(AssetError, match="named twice"):
        bake_lightmaps(runner.engine, [walls[0], walls[0]])
    bare = runner.world.spawn(Transform(), MeshRef(_quad(1.0)))
    with pytest.raises(AssetError, match=f"entity {bare} has no Material"):
        bake_lightmaps(runner.engine, [walls[0], bare])
    # Every surface is checked before any lightmap comes off: a wall keeps the one it had.
    kept = gradient_image(4)
    runner.world.get(walls[0], Material).lightmap = kept
    meshless = runner.world.spawn(Transform(), Material())
    with pytest.raises(AssetError, match=f"entity {meshless} has no MeshRef and Transform"):
        bake_lightmaps(runner.engine, [walls[0], meshless])
    assert runner.world.get(walls[0], Material).lightmap is kept
    with pytest.raises(AssetError, match="resolution must be a whole number"):
        bake_lightmaps(runner.engine, walls, resolution=2)
    assert runner.world.get(walls[0], Material).lightmap is kept
