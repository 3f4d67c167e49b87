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


# --- a second reader: the GLB's own bytes, parsed here by hand ---------------------------------

def read_glb(path) -> tuple[dict, bytes]:
    """A binary glTF's JSON and its BIN chunk, by the container's layout (glTF 2.0, 4.4)."""
    import json
    import struct

    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON"
    doc = json.loads(data[20:20 + json_length])
    bin_length, kind = struct.unpack_from("<I4s", data, 20 + json_length)
    assert kind == b"BIN\0"
    return doc, data[28 + json_length:28 + json_length + bin_length]


def accessor_array(doc: dict, data: bytes, index: int) -> np.ndarray:
    """An accessor's values as numpy reads its buffer view (floats or uint32 indices only)."""
    accessor = doc["accessors"][index]
    view = doc["bufferViews"][accessor["bufferView"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[accessor["type"]]
    dtype = {5126: np.float32, 5125: np.uint32}[accessor["componentType"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    return np.frombuffer(data, dtype, accessor["count"] * width, start).reshape(accessor["count"], width)


def trs_matrix(position, rotation, scale) -> np.ndarray:
    """A local matrix T R S in numpy, its rotation from the quaternion's formula (not glm)."""
    w, x, y, z = rotation.w, rotation.x, rotation.y, rotation.z
    turn = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    matrix = np.eye(4)
    matrix[:3, :3] = turn * np.asarray(scale, np.float64)[None, :]
    matrix[:3, 3] = position
    return matrix


def test_a_child_under_a_turned_stretched_mirroring_parent_is_written_where_the_world_draws_it(scene, tmp_path):
    """A box, a spot and a second camera parented to an entity turned, stretched and mirrored
    (scale (-1.5, 0.8, 1.2)), each with its own turn and scale: the GLB read byte by byte
    here gives each box vertex at parent T R S x child T R S (composed in numpy from the
    components' fields, not the engine's world matrix), its normals by that matrix's inverse
    transpose and its triangles wound towards them; the spot's and the camera's nodes at the
    composed place, aimed along its -Z; and the engine's loader reads the same mesh back."""
    ids: dict = {}
    parent_pose = ((0.4, 0.3, -0.6), glm.angleAxis(0.6, glm.normalize(glm.vec3(0.3, 1.0, 0.2))), (-1.5, 0.8, 1.2))
    child_pose = ((0.5, 0.2, 0.1), glm.angleAxis(-0.5, glm.normalize(glm.vec3(1.0, 0.2, 0.4))), (1.0, 0.7, 1.3))

    def parented(world):
        build(world, ids)
        ids["parent"] = world.spawn(Transform(position=parent_pose[0], rotation=parent_pose[1], scale=parent_pose[2]))
        ids["child"] = world.spawn(Transform(position=child_pose[0], rotation=child_pose[1], scale=child_pose[2],
                                             parent=ids["parent"]), MeshRef(box((0.8, 0.6, 0.5))),
                                   Material(color=(0.7, 0.2, 0.2, 1.0)))
        ids["camera"] = next(entity for entity, _ in world.query_one(Camera))
        ids["second_camera"] = world.spawn(Transform(position=(0.2, 0.5, 1.0), rotation=glm.angleAxis(
            0.3, glm.vec3(0, 1, 0)), scale=(2.0, 1.0, 1.0), parent=ids["parent"]), Camera(active=False))
        world.get(ids["spot"], Transform).parent = ids["parent"]

    runner = scene(parented, (64, 48))
    runner.frame()
    world = runner.world
    assert runner.ids()[runner.ids() == ids["child"]].size > 20   # the child is drawn where it is
    path = export_scene(world, tmp_path / "scene.glb", ids["camera"], (64, 48))
    doc, data = read_glb(path)
    nodes = {node["name"]: node for node in doc["nodes"]}
    parent = trs_matrix(*parent_pose)

    def composed(entity) -> np.ndarray:
        own = world.get(entity, Transform)
        return parent @ trs_matrix(own.position, own.rotation, own.scale)

    matrix = composed(ids["child"])
    assert np.linalg.det(matrix[:3, :3]) < 0.0
    mesh = world.get(ids["child"], MeshRef).mesh
    expected_points = mesh.positions @ matrix[:3, :3].T + matrix[:3, 3]
    expected_normals = mesh.normals @ np.linalg.inv(matrix[:3, :3])
    expected_normals /= np.linalg.norm(expected_normals, axis=1, keepdims=True)
    node = nodes[str(ids["child"])]
    assert "matrix" not in node and "translation" not in node   # its place is in its vertices
    (primitive,) = doc["meshes"][node["mesh"]]["primitives"]
    points = accessor_array(doc, data, primitive["attributes"]["POSITION"])
    normals = accessor_array(doc, data, primitive["attributes"]["NORMAL"])
    np.testing.assert_allclose(points, expected_points, atol=1e-5)
    np.testing.assert_allclose(normals, expected_normals, atol=1e-5)
    triangles = accessor_array(doc, data, primitive["indices"]).reshape(-1, 3)
    corners = points[triangles]
    facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert ((facing * normals[triangles].sum(axis=1)).sum(axis=1) > 1e-6).all()   # counter-clockwise, seen from out
    (part,) = [part for part in load_model_file(path).parts if part.mesh.name.endswith(f":{ids['child']}")]
    np.testing.assert_allclose(part.mesh.positions, expected_points, atol=1e-5)

    for name in ("spot", "second_camera"):
        placed = np.array(nodes[str(ids[name])]["matrix"], np.float64).reshape(4, 4).T   # column-major
        expected = composed(ids[name])
        np.testing.assert_allclose(placed[:3, 3], expected[:3, 3], atol=1e-5, err_msg=name)
        aim = expected[:3, :3] @ (0.0, 0.0, -1.0)
        np.testing.assert_allclose(placed[:3, :3] @ (0.0, 0.0, -1.0), aim / np.linalg.norm(aim), atol=1e-5,
                                   err_msg=name)


def small_stage(world) -> None:
    """A camera over a grey floor under a dim sky."""
    look_from(world, (0.0, 2.0, 4.0), (0.0, 0.3, 0.0))
    world.spawn(Skybox(faces=[np.full((4, 4, 3), 0.02, np.float32) for _ in range(6)]))
    world.spawn(Transform(rotation=look_rotation((0, -1, 0), (0, 0, -1))), MeshRef(quad(8.0, 8.0)),
                Material(color=(0.5, 0.5, 0.5, 1.0), roughness=0.9))


def exported_glb(runner, tmp_path) -> tuple[object, dict, bytes]:
    """The runner's world after a frame exported as GLB: its path, JSON and BIN chunk."""
    runner.frame()
    camera = next(entity for entity, _ in runner.world.query_one(Camera))
    path = export_scene(runner.world, tmp_path / "scene.glb", camera, runner.size)
    return (path, *read_glb(path))


def test_a_light_coloured_past_white_is_written_white_at_most_its_intensity_taking_the_rest(scene, tmp_path):
    """A lamp of colour (2, 1, 0.5) at 3 cd and a sun of (0.5, 3, 1) at 0.4 lux: KHR_lights_punctual's
    colour is within [0, 1], so the file holds (1, 0.5, 0.25) at 6 cd and (1/6, 1, 1/3) at
    1.2 lux, the same colour x intensity (what lights a surface), and the loader reads those back."""
    def lit(world):
        small_stage(world)
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), PointLight(color=(2.0, 1.0, 0.5, 1.0), intensity=3.0,
                                                                     range=5.0))
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.3), color=(0.5, 3.0, 1.0, 1.0), intensity=0.4))

    path, doc, _ = exported_glb(scene(lit, (32, 32)), tmp_path)
    written = {light["type"]: light for light in doc["extensions"]["KHR_lights_punctual"]["lights"]}
    expected = {"point": ((1.0, 0.5, 0.25), 6.0), "directional": ((1 / 6, 1.0, 1 / 3), 1.2)}
    for kind, (color, intensity) in expected.items():
        np.testing.assert_allclose(written[kind]["color"], color, atol=1e-6, err_msg=kind)
        assert written[kind]["intensity"] == pytest.approx(intensity), kind
    read = {light.kind: light for light in load_model_file(path).lights}
    for kind, (color, intensity) in expected.items():
        np.testing.assert_allclose(np.asarray(read[kind].color) * read[kind].intensity,
                                   np.asarray(color) * intensity, rtol=1e-5, err_msg=kind)


def test_a_16_bit_map_is_written_rounded_to_8_bits(scene, tmp_path):
    """A 16-bit colour map (uint16 texels) goes into the file as an 8-bit PNG, each channel
    round(v x 255 / 65535), computed here from the texels; the loader reads those bytes back."""
    texels = np.random.default_rng(7).integers(0, 65536, (8, 8, 4), dtype=np.uint16)
    texels[..., 3] = 65535
    texels[0, 0, :3] = (128, 129, 65406)   # either side of a half step: 0.498 -> 0, 0.502 -> 1, 254.498 -> 254
    deep = TextureData(texels, name="deep")

    def stage(world):
        small_stage(world)
        world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box((0.8, 0.8, 0.8))),
                    Material(color=(1.0, 1.0, 1.0, 1.0), texture=deep))

    path, doc, data = exported_glb(scene(stage, (32, 32)), tmp_path)
    from PIL import Image

    (image,) = doc["images"]
    view = doc["bufferViews"][image["bufferView"]]
    png = Image.open(__import__("io").BytesIO(data[view["byteOffset"]:view["byteOffset"] + view["byteLength"]]))
    expected = np.floor(texels.astype(np.float64) * 255.0 / 65535.0 + 0.5).astype(np.uint8)
    assert png.mode == "RGBA"
    np.testing.assert_array_equal(np.asarray(png), expected)
    assert tuple(np.asarray(png)[0, 0, :3]) == (0, 1, 254)
    (part,) = [part for part in load_model_file(path).parts if part.texture is not None]
    np.testing.assert_array_equal(part.texture.as_8_bits(), expected)


def test_a_lightmap_and_a_cookie_are_left_out_and_the_rest_of_their_owners_written(scene, tmp_path):
    """glTF has no slot for a lightmap or a lamp's cookie: a material with a lightmap (on its
    second UV set) and a spot with a cookie export without them (no image but the colour
    map's, no map on the second UV set), the material's colour map, the spot's cone and its
    other fields are written as without them."""
    from engine.assets.mesh import box as make_box

    baked = _texture(11, "baked lightmap")
    slide = _texture(12, "slide")

    def stage(world):
        small_stage(world)
        shape = make_box((0.8, 0.8, 0.8))
        mesh = Mesh(shape.positions, shape.normals, shape.uvs, shape.indices, name="baked box",
                    second_uvs=shape.uvs.copy())
        world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(mesh),
                    Material(color=(0.8, 0.8, 0.8, 1.0), texture=CHECKER, lightmap=baked,
                             second_uv_maps=("lightmap",)))
        world.spawn(Transform(position=(0.0, 2.0, 0.5), rotation=look_rotation((0.0, -1.0, -0.2))),
                    PointLight(intensity=4.0, range=6.0, spot_angle=40.0, spot_blend=0.2, cookie=slide,
                               shadows=True))

    path, doc, _ = exported_glb(scene(stage, (32, 32)), tmp_path)
    assert [image["name"] for image in doc["images"]] == ["checker"]
    (light,) = doc["extensions"]["KHR_lights_punctual"]["lights"]
    assert light["type"] == "spot" and light["extras"] == {"speculum": {"shadows": True}}
    assert light["spot"]["outerConeAngle"] == pytest.approx(np.radians(40.0))
    (part,) = [part for part in load_model_file(path).parts if part.texture is not None]
    assert part.second_uv_maps == ()
    np.testing.assert_array_equal(part.texture.pixels, CHECKER.pixels)


@pytest.mark.parametrize("posed_by", ["skin", "morph"])
def test_a_skinned_or_morphed_mesh_is_written_at_rest(scene, tmp_path, posed_by):
    """The file is a still scene: a quad bent 1.5 up by its Skin's one joint (or by a Morph's
    target) is drawn there (its pixels in the id image above where the rest pose would be),
    and the file holds its rest positions in world space (the mesh's own vertices through
    its transform, computed here), with neither joints nor targets."""
    from components import Morph, Skin

    lift = np.array([0.0, 1.5, 0.0])

    def stage(world):
        small_stage(world)
        flat = quad(1.0, 1.0)
        count = len(flat.positions)
        if posed_by == "skin":
            joint = np.eye(4)[None].copy()
            joint[0, :3, 3] = lift
            mesh = Mesh(flat.positions, flat.normals, flat.uvs, flat.indices, name="bent",
                        joints=np.zeros((count, 1), np.uint16), weights=np.ones((count, 1), np.float32))
            pose = Skin(joint)
        else:
            offsets = np.tile(lift, (count, 1))[None].astype(np.float32)
            mesh = Mesh(flat.positions, flat.normals, flat.uvs, flat.indices, name="bent", morph_positions=offsets)
            pose = Morph((1.0,))
        world.spawn(Transform(position=(0.0, 0.6, 0.0), scale=(1.2, 1.0, 1.0)), MeshRef(mesh),
                    Material(color=(0.9, 0.2, 0.2, 1.0), double_sided=True), pose)

    runner = scene(stage, (48, 48))
    path, doc, data = exported_glb(runner, tmp_path)
    (entity,) = [entity for entity, (ref,) in runner.world.query(MeshRef) if ref.mesh.name == "bent"]
    rows = np.nonzero((runner.ids() == entity).any(axis=1))[0]
    assert rows.size > 4 and rows.max() < 14   # drawn lifted (at rest: rows 16 to 25)
    rest = quad(1.0, 1.0).positions * (1.2, 1.0, 1.0) + (0.0, 0.6, 0.0)
    (primitive,) = doc["meshes"][[node["name"] for node in doc["nodes"]].index(str(entity))]["primitives"]
    np.testing.assert_allclose(accessor_array(doc, data, primitive["attributes"]["POSITION"]), rest, atol=1e-6)
    assert set(primitive["attributes"]) == {"POSITION", "NORMAL", "TEXCOORD_0"} and "targets" not in primitive
    assert "skins" not in doc


def test_an_orthographic_camera_is_written_with_the_pictures_aspect_and_spawned_again_draws_the_same_frame(
        scene, tmp_path):
    """An orthographic camera 6 units tall seen at 64x32: glTF's orthographic camera has no
    aspect but its magnifications (a viewer's projection is x / xmag, y / ymag: glTF 2.0,
    3.10.3), so the file holds ymag 3 and xmag 6 (half the width the picture spans), the
    loader reads its height back, and the file spawned again, looking through it, draws
    what the world drew."""
    size = (64, 32)

    def stage(world):
        small_stage(world)
        camera = next(entity for entity, _ in world.query_one(Camera))
        lens = world.get(camera, Camera)
        lens.projection, lens.ortho_height = "orthographic", 6.0
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=2.0))
        for x, color in ((-2.5, (0.8, 0.2, 0.1, 1.0)), (0.0, (0.2, 0.7, 0.2, 1.0)), (2.5, (0.2, 0.3, 0.9, 1.0))):
            world.spawn(Transform(position=(x, 0.5, 0.0)), MeshRef(box((1.0, 1.0, 1.0))), Material(color=color))

    original = scene(stage, size)
    before = frame(original)
    path, doc, _ = exported_glb(original, tmp_path)
    (lens,) = doc["cameras"]
    assert lens["type"] == "orthographic"
    assert (lens["orthographic"]["xmag"], lens["orthographic"]["ymag"]) == pytest.approx((6.0, 3.0))
    (view,) = load_model_file(path).cameras
    assert view.ortho_height == pytest.approx(6.0)
    after = frame(scene(spawned(path), size))
    assert before.std() > 0.05
    assert_drawn_as_before(after, before)
