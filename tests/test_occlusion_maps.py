"""Occlusion maps (``Material.occlusion_map``, glTF's ``occlusionTexture``): the light that
comes from all round (ambient sky or hemisphere light, a sky reflection) is scaled by
``1 + strength x (red - 1)`` per pixel; a light's own light is not.

A wall facing the camera carries a map whose left half is 0 (fully occluded) and right half
1 (open).  Each pixel's half is found by casting its ray to the wall in float64; pixels
within a texel of the middle are left out (the map's filtering).  The frames are compared,
in linear light, with frames of the same wall without the map, with no light from all
round, and with the map at half strength."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Emissive,
    HemisphereLight,
    Material,
    MeshRef,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.level_file import load_level, save_level
from engine.assets.mesh import load_model, quad
from engine.assets.models import spawn_model
from engine.assets.texture_data import TextureData
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from, pixel_rays, srgb_to_linear
from tests.test_materials_from_files import write_glb

SIZE = (160, 120)
WALL_HALF = 1.0


def occlusion_pixels(size: int = 8) -> np.ndarray:
    """RGBA: red 0 on the left half of the columns (u < 0.5), 255 on the right; G, B, A 255."""
    pixels = np.full((size, size, 4), 255, np.uint8)
    pixels[:, : size // 2, 0] = 0
    return pixels


OCCLUSION = TextureData(occlusion_pixels(), name="occlusion")


def _wall(world, occlusion: bool = True, strength: float = 1.0, ambient: float = 1.0, sun: bool = False,
          chrome: str | None = None) -> None:
    look_from(world, (0.0, 1.0, 2.2), (0.0, 1.0, 0.0))
    if chrome:   # reflects the sky: no diffuse light, all of it from all round
        world.spawn(Skybox())
    else:
        world.spawn(HemisphereLight(sky=(0.6, 0.7, 0.9), ground=(0.6, 0.7, 0.9), intensity=ambient))
    if sun:
        world.spawn(DirectionalLight(direction=glm.vec3(0.2, -0.5, -1.0), intensity=1.5))
    material = Material(color=(0.8, 0.8, 0.8), metallic=1.0 if chrome else 0.0, roughness=0.05 if chrome else 1.0,
                        occlusion_map=OCCLUSION if occlusion else None, occlusion_strength=strength)
    parts = [Transform(position=(0.0, 1.0, 0.0)), MeshRef(quad(2 * WALL_HALF, 2 * WALL_HALF)), material]
    if chrome:   # the sky's reflection, or a probe's (the wall's own)
        parts.append(Reflective(chrome, mix=1.0))
    if chrome == "cube":
        parts.append(ReflectionProbe(resolution=32, refresh="once"))
    world.spawn(*parts)
    if chrome == "cube":   # something for the probe to show, behind the camera
        world.spawn(Transform(position=(0.0, 1.0, 3.0)), MeshRef(quad(4.0, 4.0)),
                    Material(color=(0.9, 0.6, 0.2), double_sided=True), Emissive(1.0))


def _halves(runner) -> tuple[np.ndarray, np.ndarray]:
    """Pixels whose ray meets the wall's occluded half, and its open half, a texel (an
    eighth of the wall) or more from the middle and from the wall's sides."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[2] / rays[..., 2]
    points = eye + rays * t[..., None]
    inside = (np.abs(points[..., 0]) < WALL_HALF - 0.05) & (np.abs(points[..., 1] - 1.0) < WALL_HALF - 0.05)
    u = (points[..., 0] + WALL_HALF) / (2 * WALL_HALF)
    # (and from the edges: the map repeats, so its filter blends u = 0 with u = 1)
    return inside & (u > 1 / 8) & (u < 0.5 - 1 / 8), inside & (u > 0.5 + 1 / 8) & (u < 1 - 1 / 8)


def _linear(rgb: np.ndarray) -> np.ndarray:
    return srgb_to_linear(rgb)


def test_an_occluded_texel_gets_none_of_the_light_from_all_round_and_an_open_one_all(scene):
    """Lit only from all round: the occluded half is black, the open half is the frame of
    the wall without a map, byte for byte; without the map the left half is lit (not a
    black frame)."""
    mapped = scene(_wall, SIZE)
    plain = scene(lambda w: _wall(w, occlusion=False), SIZE)
    mapped_rgb, plain_rgb = mapped.frame(), plain.frame()
    occluded, open_ = _halves(mapped)
    assert occluded.sum() > 800 and open_.sum() > 800, (occluded.sum(), open_.sum())
    assert _linear(plain_rgb[occluded]).mean() > 0.2
    assert mapped_rgb[occluded].max() <= 1
    np.testing.assert_array_equal(mapped_rgb[open_], plain_rgb[open_])


def test_half_strength_keeps_half_of_the_light_from_all_round(scene):
    """``occlusion_strength`` 0.5 on an occluded texel: 1 + 0.5 x (0 - 1) = half the light."""
    half = scene(lambda w: _wall(w, strength=0.5), SIZE)
    plain = scene(lambda w: _wall(w, occlusion=False), SIZE)
    half_rgb, plain_rgb = half.frame(), plain.frame()
    occluded, open_ = _halves(half)
    ratio = _linear(half_rgb[occluded]).mean(-1) / _linear(plain_rgb[occluded]).mean(-1)
    np.testing.assert_allclose(ratio, 0.5, atol=0.02)
    np.testing.assert_array_equal(half_rgb[open_], plain_rgb[open_])


def test_a_lights_own_light_is_not_occluded(scene):
    """With a sun as well, the occluded half shows the sun's light alone: the frame of the
    same wall and sun with no light from all round; the open half shows both."""
    mapped = scene(lambda w: _wall(w, sun=True), SIZE)
    sun_only = scene(lambda w: _wall(w, occlusion=False, sun=True, ambient=0.0), SIZE)
    both = scene(lambda w: _wall(w, occlusion=False, sun=True), SIZE)
    mapped_rgb, sun_rgb, both_rgb = mapped.frame(), sun_only.frame(), both.frame()
    occluded, open_ = _halves(mapped)
    assert _linear(sun_rgb[occluded]).mean() > 0.1   # the sun lights the wall
    assert np.abs(mapped_rgb[occluded].astype(int) - sun_rgb[occluded]).max() <= 1
    np.testing.assert_array_equal(mapped_rgb[open_], both_rgb[open_])


@pytest.mark.parametrize("mode", ["skybox", "cube"])
def test_a_sky_or_probe_reflection_is_occluded_too(scene, mode):
    """A chrome wall reflecting the sky, or its own probe's capture (an orange panel behind
    the camera): the occluded half reflects nothing, the open half as the wall without a
    map."""
    mapped = scene(lambda w: _wall(w, chrome=mode), SIZE)
    plain = scene(lambda w: _wall(w, occlusion=False, chrome=mode), SIZE)
    mapped_rgb, plain_rgb = mapped.frame(), plain.frame()
    occluded, open_ = _halves(mapped)
    seen = _linear(plain_rgb[open_]).mean(axis=0)
    assert (seen[0] > seen[2] + 0.1) == (mode == "cube"), seen   # the probe shows the orange panel
    assert _linear(plain_rgb[occluded]).mean() > 0.2
    assert mapped_rgb[occluded].max() <= 1
    np.testing.assert_array_equal(mapped_rgb[open_], plain_rgb[open_])


def test_the_map_is_released_with_its_last_entity(scene):
    runner = scene(_wall, SIZE)
    runner.frame()
    renderer = runner.engine.renderer
    with_map = renderer.resource_counts()["textures"]
    for entity, _ in list(runner.world.query_one(Material)):
        runner.world.delete_entity(entity)
    runner.frame()
    assert renderer.resource_counts()["textures"] == with_map - 1


# --- values ----------------------------------------------------------------------------------

@pytest.mark.parametrize("value, reason", [(1.5, "<= 1.0"), (-0.1, ">= 0.0"), (float("inf"), "finite"),
                                           ("all", "number")])
def test_a_bad_strength_is_refused_naming_the_field(value, reason):
    with pytest.raises(ComponentValueError, match=rf"Material\.occlusion_strength.*{reason}"):
        Material(occlusion_strength=value)


def test_an_occlusion_map_must_be_a_texture():
    with pytest.raises(ComponentValueError, match=r"Material\.occlusion_map must be an engine\.assets"):
        Material(occlusion_map=np.zeros((4, 4, 4), np.uint8))


def test_a_level_file_keeps_an_occlusion_map(tmp_path):
    from PIL import Image

    Image.fromarray(occlusion_pixels()).save(tmp_path / "ao.png")
    (tmp_path / "wall.toml").write_text("""[level]
name = "wall"

[[entity]]
name = "wall"
Transform = { position = [0.0, 1.0, 0.0] }
MeshRef = { mesh = { quad = [2.0, 2.0] } }
Material = { occlusion_map = { file = "ao.png" }, occlusion_strength = 0.6 }
""")
    world = World()
    names = load_level(tmp_path / "wall.toml").spawn(world)
    material = world.get(names["wall"], Material)
    np.testing.assert_array_equal(material.occlusion_map.pixels, occlusion_pixels())
    assert material.occlusion_strength == pytest.approx(0.6)
    saved = save_level(world, tmp_path / "again.toml", names, name="wall")
    assert 'occlusion_map = { file = "ao.png" }' in saved.read_text()
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["wall"], Material).occlusion_strength == pytest.approx(0.6)


def _glb(tmp_path, strength=None, name: str = "ao.glb"):
    info = {"index": 0} if strength is None else {"index": 0, "strength": strength}
    material = {"name": "walled", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0]},
                "occlusionTexture": info}
    return write_glb(tmp_path / name, quad(2.0, 2.0), material, [occlusion_pixels()[..., :3].copy()])


@pytest.mark.parametrize("strength", [None, 0.6])
def test_a_gltf_occlusion_texture_reaches_the_material(tmp_path, strength):
    world = World()
    root = spawn_model(world, _glb(tmp_path, strength))
    (part,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
    material = world.get(part, Material)
    np.testing.assert_array_equal(material.occlusion_map.pixels, occlusion_pixels())
    assert material.occlusion_strength == pytest.approx(1.0 if strength is None else strength)


def test_a_gltf_strength_out_of_range_is_refused_naming_the_material(tmp_path):
    with pytest.raises(AssetError, match=r"walled.*occlusionTexture\.strength must be a number in \[0, 1\], got 2"):
        load_model(_glb(tmp_path, 2))


def _moved(**transform) -> dict:
    return {"index": 0, "extensions": {"KHR_texture_transform": transform}}


@pytest.mark.parametrize("info, maps, reason", [
    ({"index": 0, "texCoord": 1}, {}, "it reads TEXCOORD_1, which mesh 0's primitive 0 does not have"),
    (_moved(texCoord=1), {}, "it reads TEXCOORD_1, which mesh 0's primitive 0 does not have"),
    ({"index": 0, "texCoord": "1"}, {}, "its texCoord is '1', not a UV set's number"),
    (_moved(scale=[2, 2]), {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": _moved(rotation=0.4)},
     "a material's maps read two UV sets at most .* its others read TEXCOORD_0 and TEXCOORD_0 moved by a "
     "KHR_texture_transform")])
def test_a_map_on_uvs_the_engine_does_not_read_is_left_out_with_a_warning(tmp_path, info, maps, reason):
    """A slot reading a UV set its mesh lacks, or a third pair of UV set and transform in
    its material (the mesh carries two: engine/assets/gltf_uv_sets.py), would be drawn in
    the wrong place: the map is left out, and a warning names the material, the slot and
    why; the rest of the material is read."""
    material = {"name": "walled", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.3, 1.0], **maps},
                "occlusionTexture": info}
    path = write_glb(tmp_path / "ao.glb", quad(2.0, 2.0), material, [occlusion_pixels()[..., :3].copy()])
    with pytest.warns(UserWarning, match=rf"walled.*occlusionTexture: .*{reason}.*the map is left out"):
        (part,) = load_model(path)
    assert part.occlusion_map is None
    assert part.color[:3] == pytest.approx((0.8, 0.5, 0.3), abs=1 / 255)   # (trimesh keeps it as bytes)
    if maps:   # (the other two pairs are read: the first set and the second)
        assert part.texture is not None and part.metallic_roughness_map is not None
        assert part.second_uv_maps == ("metallic_roughness_map",) and part.mesh.second_uvs is not None


def test_a_file_requiring_an_extension_the_engine_does_not_read_is_refused(tmp_path):
    material = {"name": "walled", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.3, 1.0]}}
    path = write_glb(tmp_path / "lit.glb", quad(2.0, 2.0), material, [],
                     {"extensionsUsed": ["EXT_lights_image_based"],
                      "extensionsRequired": ["EXT_lights_image_based"]})
    with pytest.raises(AssetError, match=r"lit\.glb.*requires the glTF extension EXT_lights_image_based, "
                                         r"which the engine does not read"):
        load_model(path)


def test_occlusion_packed_with_metallic_roughness_is_read_from_that_one_map(scene, tmp_path):
    """glTF's packed occlusion-roughness-metallic image (both slots naming one texture): the
    material's two maps are one image, drawn from one GPU texture and one sampler (the
    occlusion from its red); the frame equals the same material given the occlusion as an
    image of its own (a copy), which takes a second texture."""
    orm = occlusion_pixels()
    orm[..., 1], orm[..., 2] = 255, 0   # roughness 1, metallic 0; red: occluded left, open right
    material = {"name": "packed", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0],
                                                            "metallicRoughnessTexture": {"index": 0}},
                "occlusionTexture": {"index": 0}}
    path = write_glb(tmp_path / "orm.glb", quad(2.0, 2.0), material, [orm[..., :3].copy()])
    (part,) = load_model(path)
    assert part.occlusion_map is part.metallic_roughness_map

    def build(world, packed):
        look_from(world, (0.0, 1.0, 2.2), (0.0, 1.0, 0.0))
        world.spawn(HemisphereLight(sky=(0.6, 0.7, 0.9), ground=(0.6, 0.7, 0.9), intensity=1.0))
        root = spawn_model(world, path, position=(0.0, 1.0, 0.0))
        if not packed:
            (entity,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
            own = world.get(entity, Material)
            own.occlusion_map = TextureData(own.occlusion_map.pixels.copy(), name="a copy")
    packed, separate = scene(lambda w: build(w, True), SIZE), scene(lambda w: build(w, False), SIZE)
    packed_rgb, separate_rgb = packed.frame(), separate.frame()
    occluded, open_ = _halves(packed)
    assert packed_rgb[occluded].max() <= 1 and srgb_to_linear(packed_rgb[open_]).mean() > 0.2
    np.testing.assert_array_equal(packed_rgb, separate_rgb)
    counts = [runner.engine.renderer.resource_counts()["textures"] for runner in (packed, separate)]
    assert counts[1] == counts[0] + 1, counts
