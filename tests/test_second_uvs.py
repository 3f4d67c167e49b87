"""A second UV set (``Mesh.second_uvs``, glTF's TEXCOORD_1) and the maps that read it
(``Material.second_uv_maps``): each map drawn at the set it names, checked against the same
map on a mesh whose only set is that one (a second path: no second set at all), in the main
view, both reflection paths, a probe's faces and the sun's shadow of a cutout; and refused
plainly where the mesh has no second set."""
from __future__ import annotations

import numpy as np
import pytest

from components import ComponentValueError, Emissive, HemisphereLight, Material, MeshRef, Mirror, Transform
from engine.assets.mesh import Mesh, box, quad
from engine.assets.texture_data import TextureData
from engine.core.errors import AssetError
from engine.core.world import World
from tests.test_skinning import frame_of, lit, same_picture

N = 8  # the sheet's cells a side


def sheet_arrays():
    """A 2 x 2 sheet standing in the xy plane at z = 0 from y = 0.5 to 2.5, facing +z: its
    positions, normals, triangles, and two unwrappings of it: ``first`` mirrored left to
    right, ``second`` turned a quarter (u along y)."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, N + 1), np.linspace(0.0, 1.0, N + 1), indexing="xy")
    u, v = u.ravel(), v.ravel()
    positions = np.stack([u * 2 - 1, v * 2 + 0.5, np.zeros(u.size)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (u.size, 1))
    triangles = []
    for row in range(N):
        for column in range(N):
            a = row * (N + 1) + column
            triangles += [(a, a + 1, a + N + 2), (a, a + N + 2, a + N + 1)]
    return positions, normals, np.array(triangles), np.stack([1.0 - u, v], axis=1), np.stack([v, u], axis=1)


def two_sets() -> Mesh:
    positions, normals, triangles, first, second = sheet_arrays()
    return Mesh(positions, normals, first, triangles, name="two sets", second_uvs=second)


def only(which: str) -> Mesh:
    """The sheet with one set: the first unwrapping or the second (the reference's mesh)."""
    positions, normals, triangles, first, second = sheet_arrays()
    return Mesh(positions, normals, first if which == "first" else second, triangles, name=f"{which} only")


def quadrants(colours, size: int = 32) -> TextureData:
    """An image of four quadrants (lower left, lower right, upper left, upper right as the UV
    square lies, v up), RGBA8."""
    pixels = np.zeros((size, size, 4), np.uint8)
    half = size // 2
    # (row 0 is the image's top: v = 1)
    for (row, column), colour in zip(((1, 0), (1, 1), (0, 0), (0, 1)), colours, strict=True):
        pixels[row * half:(row + 1) * half, column * half:(column + 1) * half] = colour
    return TextureData(pixels, name="quadrants")


COLOURS = quadrants([(230, 40, 30, 255), (40, 200, 40, 255), (30, 60, 230, 255), (240, 230, 40, 255)])
BUMPS = quadrants([(255 * (0.5 + 0.5 * x), 255 * (0.5 + 0.5 * y), 255 * (0.5 + 0.5 * z), 255)
                   for x, y, z in ((0.8, 0.0, 0.6), (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), (0.0, 0.0, 1.0))])
METAL_ROUGH = quadrants([(255, 40, 255, 255), (255, 255, 0, 255), (255, 120, 0, 255), (255, 20, 255, 255)])
OCCLUSION = quadrants([(0, 0, 0, 255), (255, 255, 255, 255), (60, 60, 60, 255), (255, 255, 255, 255)])

MAPS = {
    "texture": lambda: dict(texture=COLOURS),
    "normal_map": lambda: dict(color=(0.8, 0.8, 0.8, 1.0), normal_map=BUMPS),
    "emissive_map": lambda: dict(color=(0.05, 0.05, 0.05, 1.0), emissive_map=COLOURS),
    "metallic_roughness_map": lambda: dict(color=(0.9, 0.6, 0.3, 1.0), metallic=1.0, roughness=1.0,
                                           metallic_roughness_map=METAL_ROUGH),
    "occlusion_map": lambda: dict(color=(0.9, 0.9, 0.9, 1.0), occlusion_map=OCCLUSION),
}


def sheet(mesh: Mesh, extra=(), **material):
    """The sheet of ``mesh`` wearing ``material`` (and ``extra`` components), with light from
    all round (a hemisphere light: what an occlusion map darkens)."""
    def build(world):
        world.spawn(HemisphereLight(intensity=6.0))
        world.spawn(Transform(), MeshRef(mesh), Material(**material), *extra)
    return build


@pytest.mark.parametrize("name", list(MAPS))
def test_each_map_reads_the_set_it_is_named_for(scene, name):
    """A map named in ``second_uv_maps`` draws as the same map on the sheet whose only UVs are
    the second set, and not as it does at the first set."""
    extra = (Emissive(2.0),) if name == "emissive_map" else ()
    second = frame_of(scene, lit(sheet(two_sets(), extra, second_uv_maps=(name,), **MAPS[name]())))
    reference = frame_of(scene, lit(sheet(only("second"), extra, **MAPS[name]())))
    first = frame_of(scene, lit(sheet(two_sets(), extra, **MAPS[name]())))
    assert same_picture(second, reference)
    assert same_picture(first, frame_of(scene, lit(sheet(only("first"), extra, **MAPS[name]()))))
    assert (np.abs(second - first).max(axis=-1) > 30).sum() > 300, name


def swapped() -> Mesh:
    """The sheet with its two sets the other way round."""
    positions, normals, triangles, first, second = sheet_arrays()
    return Mesh(positions, normals, second, triangles, name="swapped", second_uvs=first)


def test_maps_of_both_sets_in_one_material(scene):
    """A colour texture at the first set and an occlusion map at the second draw as the sheet
    with its sets swapped and the choice swapped; so does glTF's packed image (occlusion in
    the metallic-roughness map's red) read at two sets."""
    both = dict(texture=COLOURS, occlusion_map=OCCLUSION)
    mixed = frame_of(scene, lit(sheet(two_sets(), second_uv_maps=("occlusion_map",), **both)))
    assert same_picture(mixed, frame_of(scene, lit(sheet(swapped(), second_uv_maps=("texture",), **both))))
    assert not same_picture(mixed, frame_of(scene, lit(sheet(two_sets(), **both))))
    packed = quadrants([(0, 200, 255, 255), (255, 40, 0, 255), (60, 120, 0, 255), (255, 255, 255, 255)])
    orm = dict(color=(0.9, 0.6, 0.3, 1.0), metallic=1.0, roughness=1.0, metallic_roughness_map=packed,
               occlusion_map=packed)
    split = frame_of(scene, lit(sheet(two_sets(), second_uv_maps=("occlusion_map",), **orm)))
    assert same_picture(split, frame_of(scene, lit(sheet(swapped(), second_uv_maps=("metallic_roughness_map",),
                                                         **orm))))
    assert not same_picture(split, frame_of(scene, lit(sheet(two_sets(), **orm))))


def mirrored(mesh: Mesh, **material):
    """The sheet (double-sided: the mirror behind sees its back) before two mirrors."""
    def build(world):
        for x in (-1.2, 1.4):
            world.spawn(Transform(position=(x, 1.2, -1.5)), MeshRef(quad(2.4, 2.5)), Mirror())
        sheet(mesh, double_sided=True, **material)(world)
    return build


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_both_reflection_paths_read_the_second_set(scene, path):
    """In the mirrors behind it, by the per-mirror path and the batched one (its geometry
    shader carries the second set), the sheet draws as the reference does."""
    def frame(build):
        runner = scene(lit(build, eye=(3.0, 1.8, 4.0), target=(0.0, 1.2, -0.5)), (160, 120))  # (its back seen aside)
        runner.engine.reflection_system.path = path
        runner.frame()
        image = runner.frame().astype(int)
        assert runner.stats.reflection_path == path and runner.stats.reflection_views == 2
        return image

    second = frame(mirrored(two_sets(), second_uv_maps=("texture",), texture=COLOURS))
    assert same_picture(second, frame(mirrored(only("second"), texture=COLOURS)))
    assert not same_picture(second, frame(mirrored(only("first"), texture=COLOURS)))


def test_a_probe_sees_the_second_set(scene):
    """A chrome ball's cube-map probe (its faces drawn in one layered pass) sees the sheet
    behind the camera as the reference sheet."""
    from components import Reflective
    from engine.assets.mesh import sphere

    view = {"eye": (0.0, 1.5, 3.5), "target": (0.0, 1.5, 1.2), "fov": 30.0}

    def ball(mesh, **material):
        def build(world):
            world.spawn(Transform(position=(0.0, 1.5, 1.2)), MeshRef(sphere(0.45)),
                        Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
            world.spawn(HemisphereLight(intensity=2.0))
            world.spawn(Transform(position=(0.0, -2.0, 4.5), scale=(3.0, 3.0, 3.0)), MeshRef(mesh),
                        Material(double_sided=True, **material))
        return build

    second = frame_of(scene, lit(ball(two_sets(), second_uv_maps=("texture",), texture=COLOURS), **view), frames=3)
    assert same_picture(second, frame_of(scene, lit(ball(only("second"), texture=COLOURS), **view), frames=3))
    assert not same_picture(second, frame_of(scene, lit(ball(only("first"), texture=COLOURS), **view), frames=3))


def test_a_cutouts_holes_and_shadow_follow_the_set_its_texture_reads(scene):
    """A cutout whose texture reads the second set: its holes, and the holes in its shadow on
    the floor and in screen-space occlusion's depth pass, are where the reference's are."""
    from components import AmbientOcclusion

    holes = np.full((32, 32, 4), 255, np.uint8)
    holes[:, :, 3] = np.where((np.arange(32) // 4) % 2 == 0, 0, 255)[None, :]   # columns of u cut away
    cut = TextureData(holes, name="holes")
    camera = (AmbientOcclusion(radius=1.0, intensity=2.0, direct_light=1.0, half_resolution=False),)
    for extras in ((), camera):
        second = frame_of(scene, lit(sheet(two_sets(), second_uv_maps=("texture",), texture=cut, alpha_cutoff=0.5),
                                     camera=extras))
        assert same_picture(second, frame_of(scene, lit(sheet(only("second"), texture=cut, alpha_cutoff=0.5),
                                                        camera=extras)))
        first = frame_of(scene, lit(sheet(only("first"), texture=cut, alpha_cutoff=0.5), camera=extras))
        floor = slice(75, 120)   # (the shadow on the floor, below the sheet)
        assert (np.abs(second[floor] - first[floor]).max(axis=-1) > 30).sum() > 100


def test_a_bad_second_set_or_choice_is_refused_when_given():
    positions, normals, triangles, first, second = sheet_arrays()
    with pytest.raises(AssetError, match=r"second_uvs must be one UV pair a vertex, shape \(81, 2\)"):
        Mesh(positions, normals, first, triangles, second_uvs=second[:-1])
    with pytest.raises(AssetError, match="second_uvs has NaN"):
        Mesh(positions, normals, first, triangles, second_uvs=np.where(second > 0.5, np.nan, second))
    with pytest.raises(ComponentValueError, match="names 'bump_map', which is not one of its maps"):
        Material(second_uv_maps=("bump_map",))
    with pytest.raises(ComponentValueError, match="names a map twice"):
        Material(second_uv_maps=["texture", "texture"])
    with pytest.raises(ComponentValueError, match="must be a list of map names"):
        Material(second_uv_maps=3)
    assert Material(second_uv_maps=["occlusion_map", "texture"]).second_uv_maps == ("texture", "occlusion_map")
    assert Material(second_uv_maps="texture").second_uv_maps == ("texture",)

    world = World()
    plain = quad(1.0, 1.0)
    with pytest.raises(ComponentValueError, match=r"names occlusion_map, but mesh 'quad' has no second UV set"):
        world.spawn(Transform(), MeshRef(plain), Material(second_uv_maps=("occlusion_map",)))
    entity = world.spawn(Transform(), MeshRef(plain), Material())
    with pytest.raises(ComponentValueError, match="has no second UV set"):
        world.get(entity, Material).second_uv_maps = ("texture",)
    assert world.get(entity, Material).second_uv_maps == ()
    both = world.spawn(Transform(), MeshRef(two_sets()), Material(second_uv_maps=("texture",)))
    with pytest.raises(ComponentValueError, match="has no second UV set"):
        world.get(both, MeshRef).mesh = box()
    assert world.get(both, MeshRef).mesh.second_uvs is not None


def test_a_bumpy_mirror_fits_the_set_its_normal_map_reads():
    """A mirror's normal map needs the UVs it reads to be a plane map: the second set, when
    named, is the one fitted (a bent second set refused, naming it; a flat one kept)."""
    positions, normals, triangles, first, second = sheet_arrays()
    bent = second ** 2
    world = World()
    fine = Mesh(positions, normals, bent, triangles, name="flat second", second_uvs=second)
    world.spawn(Transform(), MeshRef(fine), Mirror(), Material(normal_map=BUMPS, second_uv_maps=("normal_map",)))
    crooked = Mesh(positions, normals, first, triangles, name="bent second", second_uvs=bent)
    with pytest.raises(ComponentValueError, match="'bent second': its UVs are off a plane map"):
        world.spawn(Transform(), MeshRef(crooked), Mirror(), Material(normal_map=BUMPS, second_uv_maps=("normal_map",)))
    entity = world.spawn(Transform(), MeshRef(crooked), Mirror(), Material(normal_map=BUMPS))
    with pytest.raises(ComponentValueError, match="off a plane map"):
        world.get(entity, Material).second_uv_maps = ("normal_map",)


def gltf_sheet(tmp_path, occlusion_info, second=None, quantized=False, name="sheet.glb"):
    """The two-set sheet as a GLB: a base colour texture at TEXCOORD_0, an occlusion map by
    ``occlusion_info``, and TEXCOORD_1 (``second``; None: none), as float or as normalised
    uint16 (``quantized``, KHR_mesh_quantization)."""
    from tests.test_materials_from_files import write_glb
    from tests.test_model_variants import add_accessors, edit_glb

    material = {"name": "lit sheet", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0},
                "occlusionTexture": occlusion_info}
    path = write_glb(tmp_path / name, only("first"), material,
                     [COLOURS.pixels[..., :3].copy(), OCCLUSION.pixels[..., :3].copy()])
    if second is not None:
        down = second.astype(np.float32).copy()
        down[:, 1] = 1.0 - down[:, 1]   # (glTF's v counts down from the image's top)

        def add(doc):
            stored = np.round(down * 65535).astype(np.uint16) if quantized else down
            number = add_accessors(doc, [stored], normalized=frozenset({0}) if quantized else frozenset())
            doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = number
            if quantized:
                doc["extensionsUsed"] = ["KHR_mesh_quantization"]
        edit_glb(path, add)
    return path


@pytest.mark.parametrize("quantized", [False, True])
def test_a_gltf_map_at_texcoord_1_reads_the_second_set(tmp_path, quantized):
    """A glTF occlusion map whose ``texCoord`` is 1 is read, its part's mesh carrying the file's
    TEXCOORD_1 (float or normalised integers) as its second set and the map named in
    ``second_uv_maps``; the colour texture keeps the first."""
    from engine.assets.mesh import load_model

    *_, first, second = sheet_arrays()
    (part,) = load_model(gltf_sheet(tmp_path, {"index": 1, "texCoord": 1}, second, quantized))
    assert part.second_uv_maps == ("occlusion_map",)
    assert part.occlusion_map is not None and part.texture is not None
    np.testing.assert_allclose(part.mesh.uvs, first, atol=1e-6)
    np.testing.assert_allclose(part.mesh.second_uvs, second, atol=1e-4)
    world = World()
    from engine.assets.models import spawn_model
    root = spawn_model(world, gltf_sheet(tmp_path, {"index": 1, "texCoord": 1}, second, quantized, "again.glb"))
    (entity,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
    assert world.get(entity, Material).second_uv_maps == ("occlusion_map",)


def test_a_gltf_map_moved_unlike_the_others_reads_its_own_set(tmp_path):
    """An occlusion map at TEXCOORD_0 moved by its own KHR_texture_transform (offset and
    scale) while the colour texture is not: the first set is TEXCOORD_0 as it is, the second
    TEXCOORD_0 moved (worked out here as the extension's offset + scale x uv, v down)."""
    from engine.assets.mesh import load_model

    *_, first, _ = sheet_arrays()
    moved = {"index": 1, "extensions": {"KHR_texture_transform": {"offset": [0.25, 0.5], "scale": [2.0, 3.0]}}}
    (part,) = load_model(gltf_sheet(tmp_path, moved))
    down = np.stack([first[:, 0], 1.0 - first[:, 1]], axis=1) * (2.0, 3.0) + (0.25, 0.5)
    np.testing.assert_allclose(part.mesh.uvs, first, atol=1e-6)
    np.testing.assert_allclose(part.mesh.second_uvs, np.stack([down[:, 0], 1.0 - down[:, 1]], axis=1), atol=1e-5)
    assert part.second_uv_maps == ("occlusion_map",)


def test_a_gltf_mesh_keeps_its_texcoord_1_for_a_game_to_use(tmp_path):
    """A mesh whose file has TEXCOORD_1 that no map reads keeps it as its second set (a game
    may give it a lightmap); one without has none."""
    from engine.assets.mesh import load_model

    *_, second = sheet_arrays()
    (part,) = load_model(gltf_sheet(tmp_path, {"index": 1}, second))
    assert part.second_uv_maps == ()
    np.testing.assert_allclose(part.mesh.second_uvs, second, atol=1e-6)
    (plain,) = load_model(gltf_sheet(tmp_path, {"index": 1}, name="plain.glb"))
    assert plain.mesh.second_uvs is None


def test_a_level_file_names_the_maps_of_the_second_set_and_a_save_keeps_them(tmp_path):
    """``second_uv_maps`` in a level file: on a model file's mesh with TEXCOORD_1 it is read
    and saved again; on a box (no second set) the load fails naming the line and the mesh."""
    from PIL import Image

    from engine.assets.level_file import LevelError, load_level
    from engine.assets.level_save import save_level

    *_, second = sheet_arrays()
    gltf_sheet(tmp_path, {"index": 1}, second, name="sheet.glb")
    Image.fromarray(np.full((4, 4, 3), 128, np.uint8)).save(tmp_path / "ao.png")
    text = """[level]
name = "uv"

[[entity]]
name = "wall"
Transform = {{}}
MeshRef = {{ mesh = {mesh} }}
Material = {{ occlusion_map = {{ file = "ao.png" }}, second_uv_maps = ["occlusion_map"] }}
"""
    (tmp_path / "sheet.toml").write_text(text.format(mesh='{ file = "sheet.glb" }'))
    world = World()
    names = load_level(tmp_path / "sheet.toml").spawn(world)
    assert world.get(names["wall"], Material).second_uv_maps == ("occlusion_map",)
    saved = save_level(world, tmp_path / "again.toml", names, name="uv")
    assert 'second_uv_maps = ["occlusion_map"]' in saved.read_text()
    again = World()
    assert again.get(load_level(saved).spawn(again)["wall"], Material).second_uv_maps == ("occlusion_map",)
    (tmp_path / "box.toml").write_text(text.format(mesh="{ box = [1, 1, 1] }"))
    with pytest.raises(LevelError, match=r"box\.toml:\d+: entity 'wall': .*mesh 'box' has no second UV set"):
        load_level(tmp_path / "box.toml").spawn(World())


def test_a_choice_changed_is_drawn_the_next_frame_and_the_old_batch_goes(scene):
    """``second_uv_maps`` set on a drawn sheet: the next frame reads the second set (its batch
    of the SECOND_UV_MAPS build in place of the plain one, which is dropped); taken back, the
    first again."""
    holder = {}

    def build(world):
        world.spawn(HemisphereLight(intensity=6.0))
        holder["sheet"] = world.spawn(Transform(), MeshRef(two_sets()), Material(texture=COLOURS))

    runner = scene(lit(build), (160, 120))
    runner.frame()
    first = runner.frame().astype(int)
    material = runner.world.get(holder["sheet"], Material)
    material.second_uv_maps = ("texture",)
    second = runner.frame().astype(int)
    assert same_picture(second, frame_of(scene, lit(sheet(only("second"), texture=COLOURS))))
    assert [b.second_uv_maps for b in runner.engine.renderer.batches.values() if b.count and b.texture] == [1]
    material.second_uv_maps = ()
    assert same_picture(runner.frame().astype(int), first)
