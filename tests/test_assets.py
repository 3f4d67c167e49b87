"""Mesh files through trimesh: what a file says arrives in the mesh, the material and the
spawned components; a bad file is a clear AssetError and leaves the world untouched.

Every file is written at test time into tmp_path (text OBJ/MTL/PLY/STL, or trimesh export).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from pyglm import glm
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from components import ComponentValueError, Emissive, Material, MeshRef, Mirror, Reflective, Transform
from engine.assets.mesh import Mesh, box, load_model
from engine.assets.models import spawn_model
from engine.assets.texture_data import TextureData, load_texture, ripple_normal_map, wave_normal_map
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import srgb_to_linear

# A quad in the XY plane whose file normals lean towards +Y: trimesh would compute (0, 0, 1),
# so seeing these proves the file's normals are used.
QUAD_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
QUAD_VT = [(0.25, 0.5), (0.75, 0.5), (0.75, 1.0), (0.25, 1.0)]
QUAD_VN = (0.0, 0.6, 0.8)
TEXTURE = np.array([[[255, 0, 0, 255], [0, 255, 0, 128]],
                    [[0, 0, 255, 255], [255, 255, 255, 0]]], np.uint8)


@pytest.fixture
def world():
    w = World("assets")
    try:
        yield w
    finally:
        w.close()


def write_obj(directory: Path, name: str, mtl: str | None = None, texture: np.ndarray | None = None) -> Path:
    """The lean-normal quad as ``name``.obj, with ``mtl`` (MTL statements) as material ``m``."""
    lines = []
    if mtl is not None:
        lines += [f"mtllib {name}.mtl"]
        body = f"newmtl m\n{mtl}\n"
        if texture is not None:
            Image.fromarray(texture).save(directory / f"{name}.png")
            body += f"map_Kd {name}.png\n"
        (directory / f"{name}.mtl").write_text(body)
    lines += [f"v {x} {y} {z}" for x, y, z in QUAD_V]
    lines += [f"vt {u} {v}" for u, v in QUAD_VT]
    lines += ["vn {} {} {}".format(*QUAD_VN)]
    if mtl is not None:
        lines += ["usemtl m"]
    lines += ["f 1/1/1 2/2/1 3/3/1", "f 1/1/1 3/3/1 4/4/1"]
    path = directory / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def mesh_obj_text(mesh: Mesh) -> str:
    """An engine Mesh as OBJ text (one v/vt/vn per vertex)."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.normals]
    lines += ["usemtl m"] + ["f " + " ".join(f"{i + 1}/{i + 1}/{i + 1}" for i in tri) for tri in mesh.indices]
    return "\n".join(lines) + "\n"


def children(world: World, root: int) -> list[int]:
    return sorted(e for e, (t,) in world.query(Transform) if t.parent == root)


# --- OBJ + MTL -----------------------------------------------------------------------------

def test_obj_normals_uvs_colour_alpha_and_pbr_values(tmp_path):
    path = write_obj(tmp_path, "quad", "Kd 0.5 0.25 0.125\nd 0.4\nPm 0.3\nPr 0.7")
    (part,) = load_model(path)
    np.testing.assert_allclose(part.mesh.normals, np.tile(QUAD_VN, (4, 1)), atol=1e-6)
    order = np.lexsort(part.mesh.positions.T[::-1])     # vertex order is trimesh's business
    expected_order = np.lexsort(np.array(QUAD_V, float).T[::-1])
    np.testing.assert_allclose(part.mesh.uvs[order], np.array(QUAD_VT)[expected_order], atol=1e-6)
    assert part.color == pytest.approx((0.5, 0.25, 0.125, 0.4), abs=1e-6)   # exact floats, not uint8
    assert part.metallic == pytest.approx(0.3) and part.roughness == pytest.approx(0.7)
    assert part.reflectivity == pytest.approx(0.3)
    assert part.texture is None and part.emissive_factor == 0.0
    assert part.mesh.name == "quad.obj:quad.obj" or part.mesh.name.startswith("quad.obj:")


def test_obj_transparency_given_as_tr(tmp_path):
    (part,) = load_model(write_obj(tmp_path, "tr", "Kd 1 1 1\nTr 0.25"))
    assert part.color[3] == pytest.approx(0.75)


@pytest.mark.parametrize("kd, ke, factor", [
    ((0.5, 0.5, 0.5), (1.0, 1.0, 1.0), 2.0),            # emissive = 2 x diffuse
    ((0.2, 0.4, 0.1), (0.6, 1.2, 0.3), 3.0),            # coloured: ratio on the strongest channel
    ((0.0, 0.0, 0.8), (0.0, 0.0, 0.4), 0.5),            # a pure-blue lamp
])
def test_obj_emissive_factor_is_emissive_over_diffuse(tmp_path, world, kd, ke, factor):
    mtl = "Kd {} {} {}\nKe {} {} {}".format(*kd, *ke)
    (part,) = load_model(write_obj(tmp_path, "lamp", mtl))
    assert part.emissive_factor == pytest.approx(factor, rel=1e-6)

    root = spawn_model(world, tmp_path / "lamp.obj")
    (child,) = children(world, root)
    assert world.get(child, Emissive).power == pytest.approx(factor, rel=1e-6)
    assert tuple(world.get(child, Material).color) == pytest.approx((*kd, 1.0))
    assert not world.has(child, Reflective)


def test_obj_without_emission_or_metal_spawns_plain_entity(tmp_path, world):
    root = spawn_model(world, write_obj(tmp_path, "plain", "Kd 0.3 0.3 0.3\nKe 0 0 0"))
    (child,) = children(world, root)
    assert world.has(child, MeshRef) and world.has(child, Material)
    assert not world.has(child, Emissive) and not world.has(child, Reflective)


def test_flat_reflective_obj_becomes_a_mirror(tmp_path, world):
    """Material detection from the asset: reflectivity > 0 on a flat mesh (a flat bounding
    box) means a planar mirror."""
    root = spawn_model(world, write_obj(tmp_path, "glass", "Kd 0.9 0.9 0.9\nPm 0.6\nPr 0.1"))
    (child,) = children(world, root)
    mirror = world.get(child, Mirror)
    assert mirror.reflect_rate == pytest.approx(0.6) and mirror.roughness == pytest.approx(0.1)
    assert not world.has(child, Reflective)
    assert world.get(child, Material).metallic == pytest.approx(0.6)


def test_reflective_obj_that_is_not_flat_samples_a_probe_of_its_own(tmp_path, world):
    """A curved reflective part reflects a cube-map probe (the probes stage makes it one at its
    box's centre), not only the sky (issue 27 item 7; it was Reflective("skybox"))."""
    from engine.rules.probe_rules import has_own_probe, probe_for

    path = tmp_path / "chrome.obj"
    (tmp_path / "chrome.mtl").write_text("newmtl m\nKd 0.9 0.9 0.9\nPm 0.6\nPr 0.1\n")
    path.write_text("mtllib chrome.mtl\n" + mesh_obj_text(box()))
    root = spawn_model(world, path)
    (child,) = children(world, root)
    reflective = world.get(child, Reflective)
    assert reflective.mode == "cube" and reflective.mix == pytest.approx(0.6)
    assert has_own_probe(world, child) and probe_for(world, child) == child
    assert not world.has(child, Mirror)
    assert world.get(child, Material).roughness == pytest.approx(0.1)


def test_obj_map_kd_texture_with_alpha(tmp_path, world):
    (part,) = load_model(write_obj(tmp_path, "tex", "Kd 1 1 1", texture=TEXTURE))
    assert part.texture is not None
    np.testing.assert_array_equal(part.texture.pixels, TEXTURE)   # row 0 at the top, as in the PNG
    assert part.texture.has_alpha and part.texture.size == (2, 2)

    root = spawn_model(world, tmp_path / "tex.obj")
    (child,) = children(world, root)
    np.testing.assert_array_equal(world.get(child, Material).texture.pixels, TEXTURE)


def test_obj_without_material_keeps_engine_defaults(tmp_path):
    (part,) = load_model(write_obj(tmp_path, "bare"))          # UVs but no mtllib
    assert part.texture is None                               # not trimesh's grey placeholder
    assert part.color == (0.8, 0.8, 0.8, 1.0)
    assert part.metallic == 0.0 and part.emissive_factor == 0.0


def test_obj_normals_are_made_unit_and_zero_ones_recomputed(tmp_path):
    path = tmp_path / "normals.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 2\nvn 0 0 0\nf 1//1 2//1 3//2\n")
    (part,) = load_model(path)
    np.testing.assert_allclose(part.mesh.normals, np.tile((0.0, 0.0, 1.0), (3, 1)), atol=1e-6)


# --- GLB (glTF PBR) -------------------------------------------------------------------------

def write_glb(path: Path, *, base=(0.5, 0.25, 0.125, 0.75), metallic=0.8, roughness=0.3,
              emissive=(1.0, 0.5, 0.25), texture=TEXTURE) -> tuple[trimesh.Trimesh, np.ndarray]:
    mesh = trimesh.creation.box()
    uv = np.random.default_rng(3).random((len(mesh.vertices), 2))
    material = PBRMaterial(baseColorFactor=list(base), metallicFactor=metallic, roughnessFactor=roughness,
                           emissiveFactor=list(emissive),
                           baseColorTexture=Image.fromarray(texture) if texture is not None else None)
    mesh.visual = TextureVisuals(uv=uv, material=material)
    normals = np.array(mesh.vertex_normals)
    mesh.export(path)
    return mesh, normals


def test_glb_pbr_material_normals_uvs_texture(tmp_path, world):
    source, normals = write_glb(tmp_path / "pbr.glb")
    (part,) = load_model(tmp_path / "pbr.glb")
    # trimesh keeps glTF's base colour as uint8, so compare to 1/255.  The file gives no
    # alphaMode: OPAQUE, whose alpha (0.75 here) glTF ignores.
    assert part.color == pytest.approx((0.5, 0.25, 0.125, 1.0), abs=1 / 255)
    assert part.metallic == pytest.approx(0.8) and part.roughness == pytest.approx(0.3)
    assert part.reflectivity == pytest.approx(0.8)
    assert part.emissive_factor == pytest.approx(2.0, rel=1e-2)
    np.testing.assert_allclose(part.mesh.positions, source.vertices, atol=1e-6)
    np.testing.assert_allclose(part.mesh.normals, normals, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(part.mesh.normals, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(part.mesh.uvs, source.visual.uv, atol=1e-6)
    np.testing.assert_array_equal(part.texture.pixels, TEXTURE)

    root = spawn_model(world, tmp_path / "pbr.glb", position=(0.0, 1.0, 0.0))
    (child,) = children(world, root)
    assert world.get(root, Transform).position == glm.vec3(0.0, 1.0, 0.0)
    assert world.get(child, Emissive).power == pytest.approx(2.0, rel=1e-2)
    assert world.get(child, Reflective).mix == pytest.approx(0.8)
    assert world.get(child, Material).color.w == 1.0   # OPAQUE: the alpha ignored
    assert world.get(child, Material).texture is not None


def test_glb_base_colour_is_read_as_the_file_writes_it_not_in_8_bits(tmp_path):
    """trimesh keeps baseColorFactor as uint8: a step of 1/255 in linear light, 18% of a dark
    0.01.  The loader reads the file's own floats; a factor that is not four finite numbers
    is an error naming the material."""
    from tests.test_model_variants import edit_glb

    write_glb(tmp_path / "dark.glb", texture=None)

    def dark(doc):
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.01, 0.004, 0.5, 1.0]

    (part,) = load_model(edit_glb(tmp_path / "dark.glb", dark))
    assert part.color == pytest.approx((0.01, 0.004, 0.5, 1.0), abs=1e-9)

    def bad(doc):
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.01, 0.5, 1.0]   # (three)

    with pytest.raises(AssetError, match="baseColorFactor must be four finite numbers"):
        load_model(edit_glb(tmp_path / "dark.glb", bad))


def test_glb_dielectric_without_emission(tmp_path, world):
    write_glb(tmp_path / "dull.glb", metallic=0.0, emissive=(0.0, 0.0, 0.0), texture=None)
    (part,) = load_model(tmp_path / "dull.glb")
    assert part.texture is None and part.emissive_factor == 0.0 and part.reflectivity == 0.0
    root = spawn_model(world, tmp_path / "dull.glb")
    (child,) = children(world, root)
    assert not world.has(child, Emissive) and not world.has(child, Reflective)


def test_glb_nodes_become_children_with_their_transforms(tmp_path, world):
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(), node_name="moved", geom_name="moved",
                       transform=trimesh.transformations.translation_matrix([1.0, 2.0, 3.0]))
    turned = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]) @ np.diag([2.0, 2.0, 2.0, 1.0])
    scene.add_geometry(trimesh.creation.icosphere(1), node_name="turned", geom_name="turned", transform=turned)
    scene.add_geometry(trimesh.creation.box(), node_name="hidden", geom_name="hidden",
                       transform=np.diag([1.0, 0.0, 1.0, 1.0]))         # scaled to nothing
    scene.export(tmp_path / "nodes.glb")

    root = spawn_model(world, tmp_path / "nodes.glb")
    transforms = [world.get(e, Transform) for e in children(world, root)]
    assert len(transforms) == 2                                         # the hidden node is skipped
    by_x = sorted(transforms, key=lambda t: t.position.x)
    turned_t, moved_t = by_x
    assert tuple(moved_t.position) == pytest.approx((1.0, 2.0, 3.0))
    assert tuple(moved_t.scale) == pytest.approx((1.0, 1.0, 1.0))
    assert tuple(turned_t.scale) == pytest.approx((2.0, 2.0, 2.0))
    for axis in np.eye(3):
        np.testing.assert_allclose(turned_t.rotation * glm.vec3(*axis), turned[:3, :3] @ axis / 2.0, atol=1e-5)


# --- PLY, STL -------------------------------------------------------------------------------

def test_ply_vertex_colours_and_normals(tmp_path):
    mesh = trimesh.creation.icosphere(1)
    mesh.visual.vertex_colors = np.tile([255, 0, 0, 255], (len(mesh.vertices), 1))
    mesh.export(tmp_path / "red.ply")
    (part,) = load_model(tmp_path / "red.ply")
    # The colours are the mesh's, a vertex each (sRGB decoded); the material's colour is white.
    assert part.color == pytest.approx((1.0, 1.0, 1.0, 1.0))
    np.testing.assert_allclose(part.mesh.colors, np.tile([1.0, 0.0, 0.0], (len(mesh.vertices), 1)))
    normals = part.mesh.normals
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    assert (np.einsum("ij,ij->i", normals, part.mesh.positions) > 0.8).all()  # smooth, outward


def test_ply_ascii_written_by_hand(tmp_path):
    path = tmp_path / "tri.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    (part,) = load_model(path)
    np.testing.assert_allclose(part.mesh.normals, np.tile((0.0, 0.0, 1.0), (3, 1)), atol=1e-6)
    assert part.color == (0.8, 0.8, 0.8, 1.0)


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
def test_stl_has_outward_flat_normals_and_no_uvs(tmp_path, binary):
    mesh = trimesh.creation.icosphere(1)
    path = tmp_path / "ball.stl"
    if binary:
        mesh.export(path)
    else:
        path.write_text(trimesh.exchange.stl.export_stl_ascii(mesh))
    (part,) = load_model(path)
    assert len(part.mesh.indices) == len(mesh.faces)
    np.testing.assert_allclose(np.linalg.norm(part.mesh.normals, axis=1), 1.0, atol=1e-5)
    centres = part.mesh.positions[part.mesh.indices].mean(axis=1)
    face_normals = part.mesh.normals[part.mesh.indices[:, 0]]
    assert (np.einsum("ij,ij->i", face_normals, centres) > 0.0).all()
    assert not part.mesh.uvs.any()
    assert part.texture is None and part.color == (0.8, 0.8, 0.8, 1.0)


# --- bad input ------------------------------------------------------------------------------

NAN_OBJ = "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
NAN_STL = ("solid x\nfacet normal 0 0 1\nouter loop\nvertex nan 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
           "endloop\nendfacet\nendsolid x\n")
NAN_PLY = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
           "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\ninf 1 0\n3 0 1 2\n")
GARBAGE = bytes(np.random.default_rng(5).integers(0, 256, 400, dtype=np.uint8))

BAD_FILES = [
    # (file name, contents or None for "no file", what the message must say)
    ("missing.obj", None, "no such file"),
    ("empty.obj", b"", "empty"),
    ("empty.glb", b"", "empty"),
    ("empty.stl", b"", "empty"),
    ("empty.ply", b"", "empty"),
    ("garbage.glb", GARBAGE, "cannot be parsed"),
    ("garbage.ply", GARBAGE, "cannot be parsed"),
    ("garbage.obj", GARBAGE, "no triangle meshes"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangle meshes"),
    ("badindex.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 5\n", "line 3: face index 5, but 2 vertices in the file"),
    ("badindex.ply", NAN_PLY.replace("inf", "0").replace("3 0 1 2", "3 0 1 9").encode(),
     "face index 9 is out of range (3 vertices)"),
    ("fifo.obj", "fifo", "is a FIFO, not a regular file"),
    ("folder.obj", "folder", "is a directory, not a regular file"),
    ("model.fbx", b"Kaydara FBX Binary", "unsupported type '.fbx'"),
    ("model", b"v 0 0 0\n", "unsupported type ''"),
    ("nan.obj", NAN_OBJ.encode(), "NaN or infinite"),
    ("nan.stl", NAN_STL.encode(), "NaN or infinite"),
    ("inf.ply", NAN_PLY.encode(), "NaN or infinite"),
    ("nankd.obj", None, "diffuse colour"),
    ("roughness.obj", None, "roughness 2.0 is outside 0..1"),
    ("negative_ke.obj", None, "emissive colour"),
]
BAD_MATERIALS = {"nankd.obj": "Kd nan 0.5 0.5", "roughness.obj": "Kd 1 1 1\nPr 2", "negative_ke.obj": "Ke -1 0 0"}


@pytest.mark.parametrize("name, contents, reason", BAD_FILES, ids=[f[0] for f in BAD_FILES])
def test_bad_file_is_an_asset_error_naming_file_and_reason(tmp_path, world, name, contents, reason):
    path = tmp_path / name
    if name in BAD_MATERIALS:
        path = write_obj(tmp_path, Path(name).stem, BAD_MATERIALS[name])
    elif contents == "fifo":
        os.mkfifo(path)  # refused before anything opens it: reading would block
    elif contents == "folder":
        path.mkdir()
    elif contents is not None:
        path.write_bytes(contents)
    with pytest.raises(AssetError) as info:
        load_model(path)
    message = str(info.value)
    assert str(path) in message, message
    assert reason in message.replace(str(path), "<file>"), message   # the reason, not just the file name

    before = world.spawn(Transform())
    with pytest.raises(AssetError):
        spawn_model(world, path)
    assert world.entities() == [before]        # nothing half-registered


def test_spawn_model_rejects_bad_placement_before_spawning(tmp_path, world):
    path = write_obj(tmp_path, "ok", "Kd 1 1 1")
    with pytest.raises(ComponentValueError, match="Transform.scale"):
        spawn_model(world, path, scale=(1.0, 0.0, 1.0))
    assert world.entities() == []


def test_failing_component_leaves_no_entities(tmp_path, world, monkeypatch):
    """A part whose components cannot be built fails the spawn before any entity exists."""
    import engine.assets.models

    write_glb(tmp_path / "pbr.glb")

    def broken(*args, **kwargs):
        raise ComponentValueError("Reflective.mix broken on purpose")

    monkeypatch.setattr(engine.assets.models, "Reflective", broken)
    with pytest.raises(AssetError, match=r"pbr\.glb.*Reflective\.mix"):
        spawn_model(world, tmp_path / "pbr.glb")
    assert world.entities() == []


def test_failure_while_spawning_rolls_back(tmp_path, world, monkeypatch):
    scene = trimesh.Scene()
    for i in range(3):
        scene.add_geometry(trimesh.creation.box(), node_name=f"n{i}", geom_name=f"g{i}",
                           transform=trimesh.transformations.translation_matrix([i, 0, 0]))
    scene.export(tmp_path / "three.glb")
    keep = world.spawn(Transform())
    real_spawn, calls = world.spawn, []

    def flaky_spawn(*components):
        calls.append(components)
        if len(calls) == 3:
            raise RuntimeError("out of entity ids")
        return real_spawn(*components)

    monkeypatch.setattr(world, "spawn", flaky_spawn)
    with pytest.raises(RuntimeError, match="out of entity ids"):
        spawn_model(world, tmp_path / "three.glb")
    assert world.entities() == [keep]


def test_mesh_rejects_nan_and_bad_indices_directly():
    good = box()
    positions = good.positions.copy()
    positions[0, 1] = np.nan
    with pytest.raises(AssetError, match="NaN"):
        Mesh(positions, good.normals, good.uvs, good.indices, name="nanbox")
    with pytest.raises(AssetError, match="out of range"):
        Mesh(good.positions, good.normals, good.uvs, good.indices + 100, name="far")
    with pytest.raises(AssetError, match="no triangles"):
        Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros((0, 3)), name="none")


@pytest.mark.parametrize("texture_bytes, reason", [(None, "no such file"), (b"", "cannot be decoded"),
                                                   (GARBAGE, "cannot be decoded")], ids=["missing", "empty", "garbage"])
def test_obj_texture_that_cannot_be_read_is_named(tmp_path, world, texture_bytes, reason):
    path = write_obj(tmp_path, "skin", "Kd 1 1 1\nmap_Kd -s 1 1 1 skin_tex.png")
    if texture_bytes is not None:
        (tmp_path / "skin_tex.png").write_bytes(texture_bytes)
    with pytest.raises(AssetError, match=rf"skin\.obj.*skin_tex\.png.*{reason}"):
        spawn_model(world, path)
    assert world.entities() == []


# --- texture files --------------------------------------------------------------------------

def test_load_texture_keeps_pixels_and_alpha(tmp_path):
    Image.fromarray(TEXTURE).save(tmp_path / "rgba.png")
    tex = load_texture(tmp_path / "rgba.png")
    np.testing.assert_array_equal(tex.pixels, TEXTURE)
    assert tex.has_alpha and tex.size == (2, 2) and tex.name == "rgba.png"

    grey = np.array([[0, 64, 128], [255, 32, 16]], np.uint8)      # 3 wide, 2 high, mode L
    Image.fromarray(grey).save(tmp_path / "grey.png")
    tex = load_texture(tmp_path / "grey.png")
    assert tex.size == (3, 2) and not tex.has_alpha
    np.testing.assert_array_equal(tex.pixels[..., 0], grey)
    np.testing.assert_array_equal(tex.pixels[..., 3], 255)


@pytest.mark.parametrize("name, contents, reason", [
    ("missing.png", None, "no such file"),
    ("empty.png", b"", "cannot be read as an image"),
    ("garbage.png", GARBAGE, "cannot be read as an image"),
    ("truncated.png", "truncate", "cannot be read as an image"),
])
def test_bad_texture_file_is_an_asset_error(tmp_path, name, contents, reason):
    path = tmp_path / name
    if contents == "truncate":
        noise = np.random.default_rng(1).integers(0, 256, (64, 64, 3), dtype=np.uint8)
        Image.fromarray(noise).save(path)
        path.write_bytes(path.read_bytes()[:200])
    elif contents is not None:
        path.write_bytes(contents)
    with pytest.raises(AssetError) as info:
        load_texture(path)
    assert str(path) in str(info.value) and reason in str(info.value)


@pytest.mark.parametrize("pixels", [np.zeros((2, 2), np.uint8), np.zeros((2, 2, 2), np.uint8),
                                    np.zeros((0, 2, 4), np.uint8), np.zeros((2, 2, 4), np.float32)],
                         ids=["2d", "two-channels", "empty", "float"])
def test_texture_data_rejects_bad_pixels(pixels):
    with pytest.raises(AssetError, match="texture 'bad'"):
        TextureData(pixels, name="bad")


def test_texture_data_adds_opaque_alpha():
    tex = TextureData(np.full((1, 2, 3), 7, np.uint8))
    assert tex.pixels.shape == (1, 2, 4) and (tex.pixels[..., 3] == 255).all() and not tex.has_alpha


# --- the ripples normal map ---------------------------------------------------------------

RIPPLE_SIZE, RIPPLE_RINGS, RIPPLE_SLOPE = 65, 4, 0.5   # odd: texel 32 is the centre, u = v = 0.5 exactly
MIDDLE = RIPPLE_SIZE // 2


def decoded(tex: TextureData) -> np.ndarray:
    """The normals a shader reads: RGB / 255 * 2 - 1 (linear data, not sRGB)."""
    return tex.pixels[..., :3].astype(np.float64) / 255.0 * 2.0 - 1.0


def ripple_uv(row: int, col: int) -> tuple[float, float]:
    return (col + 0.5) / RIPPLE_SIZE, 1.0 - (row + 0.5) / RIPPLE_SIZE   # row 0 is the top: v = 1 there


def ripple_height(u: float, v: float) -> float:
    k = RIPPLE_RINGS
    return float(np.cos(2 * np.pi * k * np.hypot(u - 0.5, v - 0.5)) / (2 * np.pi * k))


def ripple_normal(row: int, col: int) -> np.ndarray:
    """The documented normal at a texel's centre, worked out here by the chain rule:
    dh/du = dh/dr (u - 0.5) / r with dh/dr = -sin(2 pi rings r)."""
    u, v = ripple_uv(row, col)
    r = np.hypot(u - 0.5, v - 0.5)
    dh_dr = -np.sin(2 * np.pi * RIPPLE_RINGS * r)
    gradient = np.zeros(2) if r == 0 else dh_dr * np.array([u - 0.5, v - 0.5]) / r
    n = np.array([-RIPPLE_SLOPE * gradient[0], -RIPPLE_SLOPE * gradient[1], 1.0])
    return n / np.linalg.norm(n)


def test_ripple_normal_map_texels_are_the_analytic_unit_normals():
    tex = ripple_normal_map(RIPPLE_SIZE, RIPPLE_RINGS, RIPPLE_SLOPE)
    assert tex.size == (RIPPLE_SIZE, RIPPLE_SIZE) and tex.name == "ripples" and not tex.has_alpha
    n = decoded(tex)
    quantum = 1.0 / 255.0 + 1e-9                          # half a step of n * 127.5, and a hair
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=2 * quantum)
    assert (n[..., 2] > 0).all()                           # blue: out of the surface everywhere
    # The centre is a smooth crest: straight out.
    np.testing.assert_array_equal(tex.pixels[MIDDLE, MIDDLE], [128, 128, 255, 255])
    # r = 1 / (4 rings) = 1/16 is the steepest ring (|dh/dr| = 1): the texel 4 above the centre
    # (r = 4/65, 0.2% short of it) leans straight up, by the slope; the one 3 up and 3 right
    # (r = 0.065) leans along the diagonal, away from the centre.
    steep = MIDDLE - 4
    assert abs(np.hypot(*np.subtract(ripple_uv(steep, MIDDLE), 0.5)) - 1 / (4 * RIPPLE_RINGS)) < 0.002
    np.testing.assert_allclose(n[steep, MIDDLE], np.array([0.0, RIPPLE_SLOPE, 1.0]) / np.hypot(RIPPLE_SLOPE, 1),
                               atol=2 * quantum)
    diagonal = n[MIDDLE - 3, MIDDLE + 3]
    assert diagonal[0] > 0.3 and diagonal[1] > 0.3 and abs(diagonal[0] - diagonal[1]) <= 2 * quantum
    for row, col in [(steep, MIDDLE), (MIDDLE - 3, MIDDLE + 3), (MIDDLE + 7, MIDDLE - 2), (5, 60), (0, 0),
                     (MIDDLE, 40), (20, MIDDLE)]:
        np.testing.assert_allclose(n[row, col], ripple_normal(row, col), atol=quantum, err_msg=f"texel {row, col}")
    # Every texel, against the same formula.
    expected = np.array([[ripple_normal(row, col) for col in range(RIPPLE_SIZE)] for row in range(RIPPLE_SIZE)])
    np.testing.assert_allclose(n, expected, atol=quantum)


def test_ripple_normal_map_green_is_up_the_image():
    """Green is +V, and row 0 is the top of the image. Row 20 is 12 texels above the centre,
    where the height rises going outwards, i.e. up the image (found here from the heights,
    not the formula): the surface faces down the image there, so green is below the middle;
    the texel as far below the centre mirrors it."""
    tex = ripple_normal_map(RIPPLE_SIZE, RIPPLE_RINGS, RIPPLE_SLOPE)
    above, below = MIDDLE - 12, MIDDLE + 12
    assert ripple_height(*ripple_uv(above - 1, MIDDLE)) > ripple_height(*ripple_uv(above + 1, MIDDLE))
    green_above, green_below = int(tex.pixels[above, MIDDLE, 1]), int(tex.pixels[below, MIDDLE, 1])
    assert green_above < 100 and green_below > 155 and abs(green_above + green_below - 255) <= 1
    assert abs(int(tex.pixels[above, MIDDLE, 0]) - 128) <= 1   # straight above: no lean along U
    # And red is +U: the texel as far to the right leans the same way along U as this one does along V.
    assert abs(int(tex.pixels[MIDDLE, MIDDLE + 12, 0]) - green_above) <= 1


def test_ripple_normal_map_source_and_flat_slope():
    assert ripple_normal_map(64, 4).source == {"ripples": [64, 4]}
    assert ripple_normal_map(32, 2, slope=0.25, name="pond").source == {"ripples": [32, 2], "slope": 0.25,
                                                                         "name": "pond"}
    flat = ripple_normal_map(16, 3, slope=0)
    assert (flat.pixels == [128, 128, 255, 255]).all()


@pytest.mark.parametrize("kwargs, argument", [
    ({"size": 0}, "size"), ({"size": 64.0}, "size"), ({"size": True}, "size"), ({"size": 20000}, "size"),
    ({"rings": 0}, "rings"), ({"size": 8, "rings": 9}, "rings"), ({"rings": 2.5}, "rings"),
    ({"slope": -0.1}, "slope"), ({"slope": float("nan")}, "slope"), ({"slope": float("inf")}, "slope"),
    ({"slope": 101}, "slope"), ({"slope": "steep"}, "slope"), ({"slope": True}, "slope"),
])
def test_ripple_normal_map_bad_arguments_are_named(kwargs, argument):
    with pytest.raises(AssetError, match=rf"^ripples normal map 'lake': {argument} must be "):
        ripple_normal_map(**{"name": "lake", **kwargs})


def test_wave_normal_map_is_the_slope_of_a_tileable_sum_of_wave_trains():
    """Read back as slopes (-n.x / n.z along U, -n.y / n.z along V), the map is a height
    field's gradient made of ``waves`` trains, each a whole number of cycles across the tile
    (so it repeats without a seam): the slopes' discrete spectrum holds nearly all its power
    at no more than ``waves`` frequencies, every one within 2 to 2 + waves cycles a tile and
    60 degrees of +U (or its opposite), the two slope components' spectra are a gradient's
    (V's is U's times n / m at each frequency), and the steepest texel leans by ``slope``."""
    size, waves, slope = 128, 10, 0.6
    n = decoded(wave_normal_map(size, waves, slope, seed=7))
    slope_u, slope_v = -n[..., 0] / n[..., 2], n[..., 1] / n[..., 2]   # (rows run down: v's sign turned)
    spectrum_u, spectrum_v = np.fft.fft2(slope_u), np.fft.fft2(slope_v)
    power = np.abs(spectrum_u) ** 2 + np.abs(spectrum_v) ** 2
    strongest = np.argsort(power.ravel())[::-1][:2 * waves]   # each train: a frequency and its conjugate
    assert power.ravel()[strongest].sum() > 0.995 * power.sum()
    cycles_v, cycles_u = np.unravel_index(strongest, power.shape)
    cycles_u = np.where(cycles_u > size // 2, cycles_u - size, cycles_u)
    cycles_v = np.where(cycles_v > size // 2, cycles_v - size, cycles_v)
    strong = power.ravel()[strongest] > 1e-3 * power.max()
    frequency = np.hypot(cycles_u, cycles_v)[strong]
    assert frequency.min() >= 1.0 and frequency.max() <= 3.0 + waves
    angle = np.degrees(np.arctan2(np.abs(cycles_v), np.abs(cycles_u)))[strong]
    assert angle.max() <= 60.0 + 1.0
    for k in np.flatnonzero(strong):   # a gradient: (du, dv) of one sine train lean along its (m, n)
        m, w = cycles_u[k], cycles_v[k]
        row, col = np.unravel_index(strongest[k], power.shape)
        if m != 0:
            assert abs(spectrum_v[row, col] - spectrum_u[row, col] * w / m) < 0.05 * abs(spectrum_u[row, col]) + 1.0
    steepest = np.hypot(slope_u, slope_v).max()
    assert abs(steepest - slope) < 0.02


def test_wave_normal_map_source_seed_and_bad_arguments():
    assert wave_normal_map(32).source == {"waves": [32, 12]}
    assert wave_normal_map(32, 4, slope=0.25, seed=3, name="sea").source == {"waves": [32, 4], "slope": 0.25,
                                                                              "seed": 3, "name": "sea"}
    np.testing.assert_array_equal(wave_normal_map(32, 4, seed=3).pixels, wave_normal_map(32, 4, seed=3).pixels)
    assert (wave_normal_map(32, 4, seed=3).pixels != wave_normal_map(32, 4, seed=4).pixels).any()
    assert (wave_normal_map(16, 3, slope=0).pixels == [128, 128, 255, 255]).all()
    for kwargs, argument in (({"size": 0}, "size"), ({"waves": 0}, "waves"), ({"waves": 65}, "waves"),
                             ({"slope": float("nan")}, "slope"), ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed")):
        with pytest.raises(AssetError, match=rf"^waves normal map 'sea': {argument} must be "):
            wave_normal_map(**{"name": "sea", **kwargs})


def test_a_normal_map_file_loads_as_its_pixels(tmp_path):
    """A normal map file is an image like any other: load_texture keeps its bytes as they are
    (no colour conversion), RGBA or RGB."""
    tex = ripple_normal_map(32, 3)
    Image.fromarray(tex.pixels).save(tmp_path / "rgba.png")
    Image.fromarray(tex.pixels[..., :3]).save(tmp_path / "rgb.png")
    for name in ("rgba.png", "rgb.png"):
        np.testing.assert_array_equal(load_texture(tmp_path / name).pixels, tex.pixels)


# --- rendering ------------------------------------------------------------------------------

def test_emissive_obj_renders_brighter_than_its_plain_twin(tmp_path, scene):
    from components import Camera, DirectionalLight

    diffuse = (0.2, 0.1, 0.05)
    cube = mesh_obj_text(box())
    for name, extra in (("lamp", "Ke 0.4 0.2 0.1"), ("plain", "")):
        (tmp_path / f"{name}.mtl").write_text("newmtl m\nKd {} {} {}\n{}\n".format(*diffuse, extra))
        (tmp_path / f"{name}.obj").write_text(f"mtllib {name}.mtl\n" + cube)

    def build(w):
        w.spawn(Transform(position=(0.0, 0.0, 5.0)), Camera(fov_y=60.0))
        w.spawn(DirectionalLight(direction=(0, 0, -1), intensity=1.0))
        spawn_model(w, tmp_path / "plain.obj", position=(-1.2, 0.0, 0.0))
        spawn_model(w, tmp_path / "lamp.obj", position=(1.2, 0.0, 0.0))

    runner = scene(build, (160, 120))
    rgb = runner.frame()
    Image.fromarray(rgb).save(tmp_path / "emissive_obj.png")
    plain_px = runner.project((-1.2, 0.0, 0.5))
    lamp_px = runner.project((1.2, 0.0, 0.5))
    plain = srgb_to_linear(rgb[plain_px[1], plain_px[0]])
    glowing = srgb_to_linear(rgb[lamp_px[1], lamp_px[0]])
    assert plain.max() > 0.05                       # the plain cube is lit, not black
    assert (glowing > plain + 0.05).all()
    # Emissive(0.4 / 0.2 = 2) adds 2 x diffuse on top of the same lighting.
    np.testing.assert_allclose(glowing - plain, np.array(diffuse) * 2.0, atol=0.015)
