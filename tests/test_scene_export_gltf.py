"""``--export-scene``'s glTF (engine/assets/gltf_export.py): every renderable entity a node of
its world-space mesh and material, read back by the engine's own glTF loader (a second
path: trimesh's parser and the loader's material code) and checked against the world it
came from: positions and normals by glm, triangles wound to their normals, UVs, vertex
colours, every material field the loader reads; and the scene the file spawns draws the
frame the world drew."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Refractive,
    Skybox,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.mesh import Mesh, box, load_model_file, quad, sphere
from engine.assets.models import spawn_model
from engine.assets.texture_data import TextureData, wave_normal_map
from shell.capture import export_scene
from tests.support import look_from, srgb_to_linear

EYE, TARGET = (0.0, 2.5, 6.0), (0.0, 0.5, 0.0)


def _texture(seed: int, name: str, alpha: bool = False) -> TextureData:
    pixels = np.random.default_rng(seed).integers(0, 256, (8, 8, 4), dtype=np.uint8)
    if not alpha:
        pixels[..., 3] = 255
    return TextureData(pixels, name=name)


CHECKER = _texture(1, "checker")
NORMALS = TextureData(np.dstack([np.full((4, 4), v, np.uint8) for v in (140, 120, 250, 255)]), name="normals")
ROUGHNESS = _texture(2, "metal_rough")
OCCLUSION = _texture(3, "occlusion")
GLOW = _texture(4, "glow")
HOLES = _texture(5, "holes", alpha=True)


def _painted_quad() -> Mesh:
    """A quad with a colour a vertex and a second UV set."""
    base = quad(1.0, 1.0)
    colors = np.array([[1.0, 0.2, 0.1], [0.1, 1.0, 0.3], [0.2, 0.3, 1.0], [1.0, 1.0, 0.2]])
    return Mesh(base.positions, base.normals, base.uvs, base.indices, name="painted",
                colors=colors[:len(base.positions)], second_uvs=base.uvs[:, ::-1].copy())


def build(world, ids: dict) -> None:
    """A camera, a sun, a floor and one thing for each kind of material the export writes."""
    look_from(world, EYE, TARGET)
    world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.2, np.float32) for _ in range(6)]))
    world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
    ids["floor"] = world.spawn(Transform(position=(0.0, -0.01, 0.0), rotation=look_rotation((0, -1, 0), (0, 0, -1))),
                               MeshRef(quad(12.0, 12.0)), Material(color=(0.35, 0.3, 0.25, 1.0), roughness=0.9))
    ids["mapped"] = world.spawn(
        Transform(position=(-2.2, 0.5, 0.0), rotation=glm.angleAxis(0.4, glm.vec3(0, 1, 0)), scale=(1.0, 0.8, 1.2)),
        MeshRef(box((1.0, 1.0, 1.0))),
        Material(color=(0.9, 0.8, 0.7, 1.0), texture=CHECKER, normal_map=NORMALS, normal_scale=0.7,
                 metallic_roughness_map=ROUGHNESS, metallic=0.6, roughness=0.8, occlusion_map=OCCLUSION,
                 occlusion_strength=0.6))
    ids["glowing"] = world.spawn(Transform(position=(-0.8, 0.4, 0.5), scale=(1.0, 0.6, 1.4)), MeshRef(sphere(0.4)),
                                 Material(color=(0.9, 0.3, 0.05, 1.0), roughness=0.4), Emissive(3.0))
    ids["glow_map"] = world.spawn(Transform(position=(0.6, 0.4, 0.6)), MeshRef(box((0.6, 0.6, 0.6))),
                                  Material(color=(0.5, 0.5, 0.5, 1.0), emissive_map=GLOW), Emissive(0.5))
    ids["cutout"] = world.spawn(Transform(position=(1.9, 0.6, 0.0), rotation=glm.angleAxis(-0.5, glm.vec3(0, 1, 0))),
                                MeshRef(quad(1.0, 1.0)),
                                Material(color=(0.3, 0.7, 0.2, 1.0), texture=HOLES, alpha_cutoff=0.4,
                                         double_sided=True))
    ids["coated"] = world.spawn(
        Transform(position=(0.0, 0.35, -1.5), scale=(-1.0, 1.0, 1.0)),   # mirrored: its winding turns
        MeshRef(sphere(0.35)),
        Material(color=(0.2, 0.3, 0.6, 1.0), roughness=0.3, clearcoat=0.8, clearcoat_roughness=0.1,
                 sheen_color=(0.4, 0.2, 0.1), sheen_roughness=0.5, iridescence=0.5, iridescence_ior=1.4,
                 iridescence_thickness=500.0, anisotropy=0.3, anisotropy_direction=30.0, reflectance=0.7,
                 specular_color=(1.0, 0.8, 0.6), diffuse_transmission=0.2,
                 diffuse_transmission_color=(0.9, 0.5, 0.4)))
    ids["unlit"] = world.spawn(Transform(position=(1.2, 1.4, -1.0)), MeshRef(box((0.4, 0.4, 0.4))),
                               Material(color=(0.1, 0.8, 0.9, 1.0), unlit=True))
    ids["faded"] = world.spawn(Transform(position=(-1.2, 1.3, -1.2)), MeshRef(box((0.5, 0.5, 0.5))),
                               Material(color=(0.8, 0.1, 0.5, 0.5)))
    ids["lamp"] = world.spawn(Transform(position=(1.5, 1.2, 1.5)),
                              PointLight(color=(1.0, 0.8, 0.6, 1.0), intensity=3.0, range=6.0))
    ids["spot"] = world.spawn(Transform(position=(-1.5, 2.5, 1.0), rotation=look_rotation((0.3, -1.0, -0.2))),
                              PointLight(color=(0.6, 0.8, 1.0, 1.0), intensity=8.0, range=9.0, spot_angle=35.0,
                                         spot_blend=0.3))
    ids["painted"] = world.spawn(Transform(position=(0.0, 1.5, -2.5)), MeshRef(_painted_quad()),
                                 Material(color=(1.0, 1.0, 1.0, 1.0), texture=CHECKER, occlusion_map=OCCLUSION,
                                          second_uv_maps=("occlusion_map",)))


def build_surfaces(world, ids: dict) -> None:
    """build's scene with glass, a mirror and a pond."""
    build(world, ids)
    ids["glass"] = world.spawn(Transform(position=(2.5, 0.5, 1.5)), MeshRef(sphere(0.5)),
                               Material(color=(0.9, 0.95, 1.0, 0.3), roughness=0.05),
                               Refractive(ior=1.45, solid=True, dispersion=0.2))
    ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -4.0)), MeshRef(quad(2.0, 1.5)),
                                Material(color=(0.9, 0.9, 0.9, 1.0)),
                                Mirror(color=(1.0, 0.9, 0.8, 1.0), reflect_rate=0.8, roughness=0.1))
    ids["pond"] = world.spawn(Transform(position=(3.0, 0.02, -2.0), rotation=look_rotation((0, -1, 0), (0, 0, -1))),
                              MeshRef(quad(2.0, 2.0)),
                              Material(color=(0.8, 0.9, 1.0, 0.2), normal_map=wave_normal_map(32)), Mirror(),
                              Water(ior=1.33))


def _world_mesh(world, entity: int) -> tuple[np.ndarray, np.ndarray]:
    """The entity's positions and unit normals in world space, by glm, vertex by vertex."""
    matrix = world.get(entity, Transform).world
    normal_matrix = glm.transpose(glm.inverse(glm.mat3(matrix)))
    mesh = world.get(entity, MeshRef).mesh
    points = np.array([list(glm.vec3(matrix * glm.vec4(*p, 1.0))) for p in mesh.positions.tolist()])
    normals = np.array([list(glm.normalize(normal_matrix * glm.vec3(*n))) for n in mesh.normals.tolist()])
    return points, normals


def _exported(runner, tmp_path, suffix: str) -> dict[str, object]:
    camera = next(entity for entity, _ in runner.world.query_one(Camera))
    path = export_scene(runner.world, tmp_path / f"scene{suffix}", camera, (64, 48))
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # the loader reads every slot the export writes
        parts = load_model_file(path).parts
    return {part.mesh.name.rsplit(":", 1)[-1]: part for part in parts}   # ("scene.glb:<entity>")


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_the_loader_reads_back_each_entitys_world_mesh(scene, tmp_path, suffix):
    ids: dict = {}
    runner = scene(lambda world: build_surfaces(world, ids), (64, 48))
    runner.frame()
    parts = _exported(runner, tmp_path, suffix)
    assert set(parts) == {str(e) for e, _ in runner.world.query_one(MeshRef)}
    for name, entity in ids.items():
        if not runner.world.has(entity, MeshRef):
            continue
        part = parts[str(entity)]
        points, normals = _world_mesh(runner.world, entity)
        mesh = runner.world.get(entity, MeshRef).mesh
        np.testing.assert_allclose(part.mesh.positions, points, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(part.mesh.normals, normals, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(part.mesh.uvs, mesh.uvs, atol=1e-6, err_msg=name)
        np.testing.assert_array_equal(np.asarray(part.local), np.asarray(glm.mat4(1.0)))
        # Each triangle wound counter-clockwise seen from the side its normals face (a mirrored
        # transform turns the winding too)
        tri = part.mesh.positions[part.mesh.indices.reshape(-1, 3)]
        facing = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        along = (facing * part.mesh.normals[part.mesh.indices.reshape(-1, 3)].sum(axis=1)).sum(axis=1)
        assert (along > -1e-7).all() and (along > 1e-7).mean() > 0.9, name   # (a sphere's poles: no area)
    painted = parts[str(ids["painted"])].mesh
    np.testing.assert_allclose(painted.colors, runner.world.get(ids["painted"], MeshRef).mesh.colors, atol=1e-6)
    np.testing.assert_allclose(painted.second_uvs, runner.world.get(ids["painted"], MeshRef).mesh.second_uvs,
                               atol=1e-6)


def test_the_loader_reads_back_each_material(scene, tmp_path):
    ids: dict = {}
    runner = scene(lambda world: build_surfaces(world, ids), (64, 48))
    runner.frame()
    parts = _exported(runner, tmp_path, ".glb")
    world = runner.world

    def part(name: str):
        return parts[str(ids[name])]

    def same_pixels(texture, expected: TextureData) -> None:
        assert texture is not None
        np.testing.assert_array_equal(texture.pixels, expected.pixels)

    mapped, material = part("mapped"), world.get(ids["mapped"], Material)
    np.testing.assert_allclose(mapped.color, tuple(material.color), atol=1e-6)
    same_pixels(mapped.texture, CHECKER)
    same_pixels(mapped.normal_map, NORMALS)
    same_pixels(mapped.metallic_roughness_map, ROUGHNESS)
    same_pixels(mapped.occlusion_map, OCCLUSION)
    assert (mapped.metallic, mapped.roughness) == pytest.approx((0.6, 0.8))
    assert (mapped.normal_scale, mapped.occlusion_strength) == pytest.approx((0.7, 0.6))
    # Emitted colour: power x the diffuse colour (past 1: the strength extension)
    glowing = part("glowing")
    assert glowing.emissive_factor == pytest.approx(3.0, rel=1e-5)
    np.testing.assert_allclose(glowing.color, (0.9, 0.3, 0.05, 1.0), atol=1e-6)
    glow_map = part("glow_map")
    same_pixels(glow_map.emissive_map, GLOW)
    assert glow_map.emissive_factor == pytest.approx(0.5)
    cutout = part("cutout")
    assert cutout.alpha_cutoff == pytest.approx(0.4) and cutout.double_sided
    same_pixels(cutout.texture, HOLES)
    coated, material = part("coated"), world.get(ids["coated"], Material)
    for field in ("clearcoat", "clearcoat_roughness", "sheen_roughness", "iridescence", "iridescence_ior",
                  "iridescence_thickness", "anisotropy", "anisotropy_direction", "diffuse_transmission"):
        assert getattr(coated, field) == pytest.approx(getattr(material, field), rel=1e-5), field
    for field in ("sheen_color", "diffuse_transmission_color"):
        np.testing.assert_allclose(getattr(coated, field), tuple(getattr(material, field)), atol=1e-6)
    # The reflectance the shaders draw, f0 = 0.16 r^2 x specular colour (one way of writing it)
    np.testing.assert_allclose(0.16 * coated.reflectance ** 2 * np.array(coated.specular_color),
                               0.16 * 0.7 ** 2 * np.array([1.0, 0.8, 0.6]), rtol=1e-5)
    assert part("unlit").unlit and not part("faded").unlit
    assert part("faded").color[3] == pytest.approx(0.5)
    assert part("painted").second_uv_maps == ("occlusion_map",)
    glass = part("glass")
    assert (glass.transmission, glass.ior, glass.thick, glass.dispersion) == pytest.approx((0.7, 1.45, True, 0.2))
    mirror = part("mirror")   # a smooth metal of its tint, as metallic as it reflects: a mirror again
    assert (mirror.metallic, mirror.roughness, mirror.reflectivity) == pytest.approx((0.8, 0.1, 0.8))
    np.testing.assert_allclose(mirror.color, (0.9, 0.81, 0.72, 1.0), atol=1e-6)
    pond = part("pond")
    assert (pond.transmission, pond.ior, pond.metallic, pond.roughness) == pytest.approx((0.8, 1.33, 0.0, 0.0))


def test_the_exported_scene_spawned_again_draws_the_same_frame(scene, tmp_path):
    """The file spawned as a model (spawn_model) under the same sky, its camera made active,
    draws what the world it came from drew (its things, the sun, the lamp and the spot
    brought by the file), within 8-bit steps and a few edge pixels."""
    ids: dict = {}
    original = scene(lambda world: build(world, ids), (160, 120))
    original.engine.renderer.antialias = "off"
    original.frame()
    before = srgb_to_linear(original.frame())
    camera = next(entity for entity, _ in original.world.query_one(Camera))
    path = export_scene(original.world, tmp_path / "scene.glb", camera, (160, 120))

    def again(world):   # the sky alone by hand: glTF has none
        world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.2, np.float32) for _ in range(6)]))
        spawn_model(world, path)
        (camera,) = [entity for entity, _ in world.query_one(Camera)]   # the file's, made the view's
        world.get(camera, Camera).active = True

    copy = scene(again, (160, 120))
    copy.engine.renderer.antialias = "off"
    copy.frame()
    after = srgb_to_linear(copy.frame())
    assert before.std() > 0.05   # a scene, not a flat frame
    difference = np.abs(after - before).max(axis=-1)
    assert np.median(difference) < 0.004, np.median(difference)
    assert (difference > 0.05).mean() < 0.01, (difference > 0.05).mean()


def test_a_spot_under_a_mirroring_transform_is_read_back_where_it_shines(scene, tmp_path):
    """A spot whose Transform mirrors and stretches it (scale (-1, 2, 1), turned): its node keeps
    the turn and the reflection, its scale left out (``_placement``), and the loader reads
    it back at the lamp's place, shining the way the engine aims it (its world -Z)."""
    ids: dict = {}

    def mirrored(world):
        build(world, ids)
        transform = world.get(ids["spot"], Transform)
        transform.rotation = glm.angleAxis(0.7, glm.normalize(glm.vec3(1.0, 0.5, -0.3))) * transform.rotation
        transform.scale = glm.vec3(-1.0, 2.0, 1.0)

    runner = scene(mirrored, (64, 48))
    runner.frame()
    camera = next(entity for entity, _ in runner.world.query_one(Camera))
    loaded = load_model_file(export_scene(runner.world, tmp_path / "scene.glb", camera, (64, 48)))
    light = {light.name: light for light in loaded.lights}[str(ids["spot"])]
    world_matrix = runner.world.get(ids["spot"], Transform).world
    assert glm.determinant(glm.mat3(world_matrix)) < 0.0
    np.testing.assert_allclose(glm.vec3(light.local[3]), glm.vec3(world_matrix[3]), atol=1e-6)
    np.testing.assert_allclose(glm.normalize(glm.vec3(light.local * glm.vec4(0, 0, -1, 0))),
                               glm.normalize(glm.vec3(world_matrix * glm.vec4(0, 0, -1, 0))), atol=1e-6)
    assert light.spot_angle() == pytest.approx(runner.world.get(ids["spot"], PointLight).spot_angle)


def test_a_camera_under_a_mirroring_transform_is_read_back_where_it_looks(scene, tmp_path):
    """The camera's Transform mirrors and stretches it (scale (1, -1.5, 1), turned): its node
    keeps the turn and the reflection, its scale left out (``_placement``), and the loader
    reads it back at the camera's place, looking the way the engine looks (its world -Z) with
    its world +Y up, the lens as it was."""
    ids: dict = {}

    def mirrored(world):
        build(world, ids)
        camera = next(entity for entity, _ in world.query_one(Camera))
        transform = world.get(camera, Transform)
        transform.rotation = glm.angleAxis(0.4, glm.normalize(glm.vec3(0.2, 1.0, 0.1))) * transform.rotation
        transform.scale = glm.vec3(1.0, -1.5, 1.0)

    runner = scene(mirrored, (64, 48))
    runner.frame()
    camera = next(entity for entity, _ in runner.world.query_one(Camera))
    (view,) = load_model_file(export_scene(runner.world, tmp_path / "scene.glb", camera, (64, 48))).cameras
    world_matrix = runner.world.get(camera, Transform).world
    assert glm.determinant(glm.mat3(world_matrix)) < 0.0
    np.testing.assert_allclose(glm.vec3(view.local[3]), glm.vec3(world_matrix[3]), atol=1e-6)
    for axis in (glm.vec4(0, 0, -1, 0), glm.vec4(0, 1, 0, 0)):
        np.testing.assert_allclose(glm.normalize(glm.vec3(view.local * axis)),
                                   glm.normalize(glm.vec3(world_matrix * axis)), atol=1e-6)
    lens = runner.world.get(camera, Camera)
    assert (view.fov_y, view.near, view.far) == pytest.approx((lens.fov_y, lens.near, lens.far))


def test_the_loader_reads_back_the_lights_and_the_camera(scene, tmp_path):
    """KHR_lights_punctual's sun, lamp and spot and core glTF's camera, where the world has
    them: kind, colour, intensity, range, cone, place and the way each shines or looks.
    (At 64x48 this frame once took llvmpipe 145 s: its anisotropic filter walking the scaled
    sphere's silhouette, tests/test_texture_footprint.py.)"""
    ids: dict = {}
    runner = scene(lambda world: build(world, ids), (64, 48))
    runner.frame()
    camera = next(entity for entity, _ in runner.world.query_one(Camera))
    path = export_scene(runner.world, tmp_path / "scene.glb", camera, (64, 48))
    loaded = load_model_file(path)
    lights = {light.name: light for light in loaded.lights}
    world = runner.world
    (sun_entity,) = [entity for entity, _ in world.query_one(DirectionalLight)]
    sun = lights[str(sun_entity)]
    assert sun.kind == "directional" and sun.intensity == pytest.approx(2.0)
    forward = glm.normalize(glm.vec3(sun.local * glm.vec4(0, 0, -1, 0)))
    np.testing.assert_allclose(forward, glm.normalize(glm.vec3(0.3, -1.0, -0.4)), atol=1e-6)
    for name, kind in (("lamp", "point"), ("spot", "spot")):
        light, lamp = lights[str(ids[name])], world.get(ids[name], PointLight)
        transform = world.get(ids[name], Transform)
        assert light.kind == kind and light.intensity == pytest.approx(lamp.intensity)
        assert light.range == pytest.approx(lamp.range)
        np.testing.assert_allclose(light.color, tuple(lamp.color)[:3], atol=1e-6)
        np.testing.assert_allclose(glm.vec3(light.local[3]), transform.position, atol=1e-6)
        np.testing.assert_allclose(glm.vec3(light.local * glm.vec4(0, 0, -1, 0)),
                                   glm.vec3(transform.world * glm.vec4(0, 0, -1, 0)), atol=1e-6)
        assert light.spot_angle() == pytest.approx(lamp.spot_angle)
        if kind == "spot":
            assert light.spot_blend() == pytest.approx(lamp.spot_blend)
    (view,) = loaded.cameras
    lens, placed = world.get(camera, Camera), world.get(camera, Transform)
    assert (view.fov_y, view.near, view.far) == pytest.approx((lens.fov_y, lens.near, lens.far))
    np.testing.assert_allclose(glm.vec3(view.local[3]), placed.position, atol=1e-6)
    np.testing.assert_allclose(glm.vec3(view.local * glm.vec4(0, 0, -1, 0)),
                               glm.vec3(placed.world * glm.vec4(0, 0, -1, 0)), atol=1e-6)


def spawned(path):
    """A world that spawns the exported file ``path`` under a dim sky (glTF has none) and looks
    through its camera."""
    def again(world):
        world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.02, np.float32) for _ in range(6)]))
        spawn_model(world, path)
        (camera,) = [entity for entity, _ in world.query_one(Camera)]
        world.get(camera, Camera).active = True
    return again


def frame(runner):
    """The second frame, linear, without anti-aliasing."""
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())


def assert_drawn_as_before(after: np.ndarray, before: np.ndarray) -> None:
    """The file spawned again draws what the world drew: all but a few edge pixels alike."""
    difference = np.abs(after - before).max(axis=-1)
    assert np.median(difference) < 0.004 and (difference > 0.05).mean() < 0.01, (np.median(difference),
                                                                                 (difference > 0.05).mean())


def drawn_without_extras(scene, doc: dict, tmp_path) -> np.ndarray:
    """The frame of the exported file ``doc`` (its JSON) with its lights' extras taken out,
    written beside the first (any buffer file it names is there too)."""
    import json

    for light in doc["extensions"]["KHR_lights_punctual"]["lights"]:
        light.pop("extras", None)
    bare = tmp_path / "bare.gltf"
    bare.write_text(json.dumps(doc))
    return frame(scene(spawned(bare), (128, 96)))


def test_a_lamps_shape_is_read_back_from_its_extras_and_lights_as_it_did(scene, tmp_path):
    """A sphere lamp, a rectangle and a tube over a glossy floor: each exported light's
    ``extras`` hold its shape (KHR_lights_punctual has no word for one), the loader reads them
    back onto the spawned PointLights, and the file spawned again draws what the world drew
    (each highlight's shape on the floor); with the extras taken out of the file it does not."""
    import json

    lamps = {"sphere": dict(radius=0.4), "rectangle": dict(rectangle=(1.6, 0.5)), "tube": dict(length=1.6)}
    down = look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))

    def build_lamps(world):
        look_from(world, (0.0, 2.2, 4.5), (0.0, 0.0, 0.0))
        world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.02, np.float32) for _ in range(6)]))
        world.spawn(Transform(rotation=look_rotation((0, -1, 0), (0, 0, -1))), MeshRef(quad(12.0, 12.0)),
                    Material(color=(0.5, 0.5, 0.5, 1.0), roughness=0.2, metallic=0.0))
        for x, shape in zip((-2.2, 0.0, 2.2), lamps.values(), strict=True):
            world.spawn(Transform(position=(x, 1.0, -0.5), rotation=down),
                        PointLight(intensity=2.0, range=8.0, **shape))

    original = scene(build_lamps, (128, 96))
    before = frame(original)
    camera = next(entity for entity, _ in original.world.query_one(Camera))
    path = export_scene(original.world, tmp_path / "lamps.gltf", camera, (128, 96))
    doc = json.loads(path.read_text())
    written = [light.get("extras", {}).get("speculum") for light in doc["extensions"]["KHR_lights_punctual"]["lights"]]
    assert written == [{"radius": 0.4}, {"rectangle": [1.6, 0.5]}, {"length": 1.6}]
    copy = scene(spawned(path), (128, 96))
    after = frame(copy)
    made = sorted(((t.position.x, lamp) for _, (lamp, t) in copy.world.query(PointLight, Transform)),
                  key=lambda pair: pair[0])
    for (_, lamp), shape in zip(made, lamps.values(), strict=True):
        for name, value in shape.items():
            assert getattr(lamp, name) == pytest.approx(value), (name, getattr(lamp, name))
    assert_drawn_as_before(after, before)
    points = drawn_without_extras(scene, doc, tmp_path)
    assert np.abs(points - before).max(axis=-1).max() > 0.1   # (the shapes show in the frame)


def test_a_lights_engine_fields_are_read_back_from_its_extras_and_light_as_they_did(scene, tmp_path):
    """A spot wider than glTF's 90 degrees that casts shadows (a cube map, softened) and a sun
    with two cascades, a disc and no shadows: each light's ``extras`` hold what the
    extension has no word for (the fields other than their defaults), the loader makes the
    same lights again field by field, and the file spawned again draws what the world drew (a
    box's shadow and the cone's edge past 90 degrees); with the extras taken out it does not."""
    import dataclasses
    import json

    lamp_fields = dict(spot_angle=120.0, spot_blend=0.3, shadows=True, shadow_resolution=256, shadow_softness=2.0,
                       bounces=2, volumetric=0.5)
    sun_fields = dict(shadows=False, shadow_cascades=2, shadow_distance=30.0, angular_diameter=0.53)

    def build(world):
        look_from(world, (0.5, 2.6, 2.6), (0.8, 0.0, 0.0))
        world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.02, np.float32) for _ in range(6)]))
        world.spawn(Transform(rotation=look_rotation((0, -1, 0), (0, 0, -1))), MeshRef(quad(12.0, 12.0)),
                    Material(color=(0.5, 0.5, 0.5, 1.0), roughness=0.9))
        world.spawn(Transform(position=(0.6, 0.4, 0.0)), MeshRef(box((0.8, 0.8, 0.8))),
                    Material(color=(0.6, 0.3, 0.2, 1.0), roughness=0.9))
        world.spawn(Transform(position=(0.0, 1.2, 0.0), rotation=look_rotation((0.3, -1.0, 0.0), (0, 0, -1))),
                    PointLight(intensity=3.0, range=10.0, **lamp_fields))
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.3), intensity=0.2, **sun_fields))

    original = scene(build, (128, 96))
    before = frame(original)
    camera = next(entity for entity, _ in original.world.query_one(Camera))
    path = export_scene(original.world, tmp_path / "lights.gltf", camera, (128, 96))
    doc = json.loads(path.read_text())
    written = {light["type"]: light.get("extras", {}).get("speculum")
               for light in doc["extensions"]["KHR_lights_punctual"]["lights"]}
    assert written == {"spot": lamp_fields, "directional": sun_fields}, written
    copy = scene(spawned(path), (128, 96))
    after = frame(copy)
    ((_, lamp),) = list(copy.world.query_one(PointLight))
    ((_, sun),) = list(copy.world.query_one(DirectionalLight))
    ((_, lamp_was),) = list(original.world.query_one(PointLight))
    ((_, sun_was),) = list(original.world.query_one(DirectionalLight))
    for made, was, names in ((lamp, lamp_was, [*lamp_fields, "radius", "contact_shadows"]),
                             (sun, sun_was, [*sun_fields, "body", "bounces", "shadow_resolution"])):
        for name in names:
            assert getattr(made, name) == pytest.approx(getattr(was, name)), (name, getattr(made, name))
    assert {f.name for f in dataclasses.fields(PointLight)} >= set(lamp_fields)
    assert_drawn_as_before(after, before)
    plain = drawn_without_extras(scene, doc, tmp_path)
    assert ((plain - before).max(axis=-1) > 0.05).mean() > 0.05   # (the box's shadow gone)
