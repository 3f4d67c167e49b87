"""Materials from files (issue 27 item 7): glTF normal, emissive and metallic-roughness
textures and OBJ/MTL bump, norm and map_Ke maps reach the Material, and the frame shows
them; a curved reflective part samples a probe of its own.  Files are written here: a GLB
by hand (JSON and binary chunks), OBJ + MTL + PNG as text and Pillow images.  Each render is
checked against math or a second render that takes another path (a plain material with the
values the texels say, a quad turned as the map bends it)."""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.level_file import load_level, save_level
from engine.assets.mesh import Mesh, load_model, quad, sphere
from engine.assets.models import spawn_model
from engine.assets.texture_data import TextureData
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from, srgb_to_linear

# --- writing files ---------------------------------------------------------------------------


def png_bytes(pixels: np.ndarray) -> bytes:
    import io

    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="PNG")
    return out.getvalue()


def write_glb(path: Path, mesh: Mesh, material: dict | None, images: list[np.ndarray], extra: dict | None = None,
              colors: np.ndarray | None = None) -> Path:
    """One node, one mesh, one primitive, one material (``material``, the glTF JSON object;
    texture i is ``images[i]``, stored as PNG in the binary chunk; ``extra``: more top-level
    members, as ``extensionsRequired``; ``colors``: a COLOR_0 attribute, float RGBA a vertex;
    ``material`` None: none).  glTF's UVs start at the
    image's top-left: v is flipped from the engine's (bottom-up) UVs."""
    blob = bytearray()
    views, accessors = [], []

    def view(data: bytes) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob.extend(data)
        return len(views) - 1

    def accessor(array: np.ndarray, kind: str, component: int, **extra) -> int:
        accessors.append({"bufferView": view(array.tobytes()), "componentType": component, "count": len(array),
                          "type": kind, **extra})
        return len(accessors) - 1

    positions = mesh.positions.astype(np.float32)
    uv = mesh.uvs.astype(np.float32).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    attributes = {
        "POSITION": accessor(positions, "VEC3", 5126, min=positions.min(0).tolist(), max=positions.max(0).tolist()),
        "NORMAL": accessor(mesh.normals.astype(np.float32), "VEC3", 5126),
        "TEXCOORD_0": accessor(uv, "VEC2", 5126),
    }
    if colors is not None:
        attributes["COLOR_0"] = accessor(np.asarray(colors, np.float32), "VEC4", 5126)
    indices = accessor(mesh.indices.astype(np.uint32).ravel(), "SCALAR", 5125)
    image_entries = [{"bufferView": view(png_bytes(pixels)), "mimeType": "image/png"} for pixels in images]
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": attributes, "indices": indices,
                                       **({"material": 0} if material is not None else {})}]}],
           "materials": [material] if material is not None else [], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob)}]}
    doc.update(extra or {})
    if images:
        doc["images"] = image_entries
        doc["textures"] = [{"source": i} for i in range(len(images))]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    while len(blob) % 4:
        blob.append(0)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(blob), b"BIN\0") + bytes(blob)
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


def write_obj(directory: Path, mesh: Mesh, mtl: str, images: dict[str, np.ndarray]) -> Path:
    """``mesh`` as model.obj with material ``m`` from model.mtl (``mtl``: its statements),
    and the images named in it as PNG files."""
    for name, pixels in images.items():
        Image.fromarray(pixels).save(directory / name)
    (directory / "model.mtl").write_text(f"newmtl m\n{mtl}\n")
    lines = ["mtllib model.mtl"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in mesh.uvs]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.normals]
    lines += ["usemtl m"] + ["f " + " ".join(f"{i + 1}/{i + 1}/{i + 1}" for i in tri) for tri in mesh.indices]
    path = directory / "model.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def halves(size: int, left, right) -> np.ndarray:
    """A size x size RGB image: ``left`` on its left half (u < 0.5), ``right`` on the other."""
    pixels = np.empty((size, size, 3), np.uint8)
    pixels[:, : size // 2] = left
    pixels[:, size // 2:] = right
    return pixels


GLOW = (200, 120, 40)
# The emissive map: GLOW on the top-left quadrant (u < 0.5, v > 0.5), black elsewhere; the
# normal map: one normal tilted towards +U; the metallic-roughness map: rough dielectric
# (G 230, B 0) on the left, glossy metal (G 51, B 255) on the right.
EMISSIVE = np.zeros((8, 8, 3), np.uint8)
EMISSIVE[:4, :4] = GLOW
NORMALS = np.tile(np.array([166, 128, 245], np.uint8), (4, 4, 1))
METAL_ROUGH = halves(8, (0, 230, 0), (0, 51, 255))


def pbr_glb(path: Path, mesh: Mesh, **overrides) -> Path:
    material = {"name": "painted", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.3, 0.3, 1.0],
                                                             "metallicFactor": 0.9, "roughnessFactor": 0.8,
                                                             "metallicRoughnessTexture": {"index": 2}},
                "normalTexture": {"index": 1, "scale": 0.7}, "emissiveTexture": {"index": 0},
                "emissiveFactor": [1.0, 1.0, 1.0]}
    for key, value in overrides.items():
        if value is None:
            material.pop(key, None)
            material["pbrMetallicRoughness"].pop(key, None)
        elif key in ("metallicFactor", "roughnessFactor"):
            material["pbrMetallicRoughness"][key] = value
        else:
            material[key] = value
    return write_glb(path, mesh, material, [EMISSIVE, NORMALS, METAL_ROUGH])


def rgba(pixels: np.ndarray) -> np.ndarray:
    return np.concatenate([pixels, np.full(pixels.shape[:2] + (1,), 255, np.uint8)], axis=2)


# --- glTF: the components hold the file's textures -------------------------------------------

def test_a_gltf_materials_maps_reach_the_material_texel_for_texel(tmp_path):
    path = pbr_glb(tmp_path / "painted.glb", sphere(0.5, 16, 8))
    (part,) = load_model(path)
    np.testing.assert_array_equal(part.emissive_map.pixels, rgba(EMISSIVE))
    np.testing.assert_array_equal(part.normal_map.pixels, rgba(NORMALS))
    np.testing.assert_array_equal(part.metallic_roughness_map.pixels, rgba(METAL_ROUGH))
    assert part.normal_scale == pytest.approx(0.7)  # normalTexture.scale, which trimesh drops
    assert part.metallic == pytest.approx(0.9) and part.roughness == pytest.approx(0.8)
    assert part.emissive_factor == 1.0 and part.reflectivity == pytest.approx(0.9)

    world = World("gltf maps")
    try:
        root = spawn_model(world, path)
        (child,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
        material = world.get(child, Material)
        np.testing.assert_array_equal(material.emissive_map.pixels, rgba(EMISSIVE))
        np.testing.assert_array_equal(material.normal_map.pixels, rgba(NORMALS))
        np.testing.assert_array_equal(material.metallic_roughness_map.pixels, rgba(METAL_ROUGH))
        assert material.normal_scale == pytest.approx(0.7) and material.metallic == pytest.approx(0.9)
        assert world.get(child, Emissive).power == 1.0
        reflective = world.get(child, Reflective)  # curved and metallic: it samples a probe
        assert reflective.mode == "cube" and reflective.mix == pytest.approx(0.9)
    finally:
        world.close()


def test_gltf_factors_absent_beside_a_metallic_roughness_texture_are_one(tmp_path):
    """glTF: metallicFactor and roughnessFactor default to 1, so the texture is taken as it
    is (the engine's own defaults, 0 and 0.5, hold only without a texture).  A map that is
    nowhere metal makes nothing reflective."""
    dull = halves(8, (0, 200, 0), (0, 100, 0))
    material = {"pbrMetallicRoughness": {"metallicRoughnessTexture": {"index": 0}}}
    (part,) = load_model(write_glb(tmp_path / "plastic.glb", sphere(0.5, 16, 8), material, [dull]))
    assert part.metallic == 1.0 and part.roughness == 1.0
    assert part.reflectivity == 0.0 and part.normal_map is None and part.emissive_map is None


def test_an_emissive_factor_that_is_not_grey_tints_the_map_in_linear_light(tmp_path):
    path = pbr_glb(tmp_path / "tinted.glb", quad(), emissiveFactor=[0.8, 0.4, 0.2])
    (part,) = load_model(path)
    assert part.emissive_factor == pytest.approx(0.8)
    expected = srgb_to_linear(EMISSIVE) * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(srgb_to_linear(part.emissive_map.pixels[..., :3]), expected, atol=0.004)
    assert (part.emissive_map.pixels[:4, :4, 0] == GLOW[0]).all()  # the strongest channel keeps its texels


# --- rendering -------------------------------------------------------------------------------

def spawn_parts(world, parts, drop_reflective: bool = False) -> list[int]:
    """Entities of load_model's parts with the Material spawn_model would give them."""
    out = []
    for part in parts:
        out.append(world.spawn(Transform(), MeshRef(part.mesh), Material(
            color=part.color, texture=part.texture, metallic=part.metallic, roughness=part.roughness,
            normal_map=part.normal_map, normal_scale=part.normal_scale, emissive_map=part.emissive_map,
            metallic_roughness_map=part.metallic_roughness_map)))
    return out


def linear_frame(runner) -> np.ndarray:
    runner.frame()
    return srgb_to_linear(runner.frame())


def region(runner, u: tuple[float, float], v: tuple[float, float], half: float = 0.5) -> tuple[slice, slice]:
    """The pixels of the quad (side 2 x ``half``, facing the camera) between UVs ``u`` and ``v``."""
    (c0, r0), (c1, r1) = (runner.project((-half + 2 * half * u[0], -half + 2 * half * v[1], 0.0)),
                          runner.project((-half + 2 * half * u[1], -half + 2 * half * v[0], 0.0)))
    return slice(r0 + 1, r1 - 1), slice(c0 + 1, c1 - 1)


def test_a_gltf_emissive_map_glows_where_its_texels_are(scene, tmp_path):
    """The file's quad with its emissive map (GLOW on the top-left quadrant), in the dark but
    for the ambient light: the frame minus the same frame without Emissive is power x the
    texel's linear colour on that quadrant, and nothing elsewhere."""
    path = pbr_glb(tmp_path / "sign.glb", quad(), metallicFactor=None, roughnessFactor=None,
                   metallicRoughnessTexture=None, normalTexture=None)
    path_plain = write_glb(tmp_path / "plain.glb", quad(), {"pbrMetallicRoughness": {
        "baseColorFactor": [0.3, 0.3, 0.3, 1.0]}}, [])
    frames = {}
    for name, model in (("glowing", path), ("plain", path_plain)):
        def build(world, model=model):
            look_from(world, (0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), fov=40.0)
            spawn_model(world, model)
        runner = scene(build, (96, 96))
        frames[name] = linear_frame(runner)
        cells = {q: region(runner, u, v) for q, u, v in (("top left", (0.05, 0.4), (0.6, 0.95)),
                                                         ("top right", (0.6, 0.95), (0.6, 0.95)),
                                                         ("bottom left", (0.05, 0.4), (0.05, 0.4)))}
        runner.close()
    glow = frames["glowing"] - frames["plain"]
    expected = srgb_to_linear(np.array(GLOW))  # power 1 (emissiveFactor 1) x the texel
    lit = glow[cells["top left"]].reshape(-1, 3)
    assert len(lit) > 100
    np.testing.assert_allclose(np.median(lit, axis=0), expected, atol=0.02)
    for dark in ("top right", "bottom left"):
        assert np.abs(glow[cells[dark]]).max() < 0.01, dark


@pytest.mark.parametrize("reflective", [False, True])
def test_a_metallic_roughness_map_shades_each_half_as_its_texels_say(scene, tmp_path, reflective):
    """The map's left half is rough dielectric, its right glossy metal: each half of the quad
    equals a quad with no map whose metallic and roughness are the factors times those texels
    (the highlight of a light behind the camera), and with Reflective("skybox") the metal
    half reflects the sky by the slot while the dielectric half, which the map's blue says is
    not metal, keeps the plain material's light, its environment reflection with it."""
    (part,) = load_model(pbr_glb(tmp_path / "trim.glb", quad(), metallicFactor=1.0, roughnessFactor=1.0,
                                 normalTexture=None, emissiveTexture=None))

    def build(material: Material | None):
        def b(world):
            look_from(world, (0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), fov=40.0)
            world.spawn(DirectionalLight(direction=(0.15, -0.1, -1.0), intensity=3.0))
            world.spawn(Skybox())
            if material is None:
                (entity,) = spawn_parts(world, [part])
            else:
                entity = world.spawn(Transform(), MeshRef(part.mesh), material)
            if reflective and (material is None or material.metallic > 0.0):
                world.add_component(entity, Reflective("skybox", mix=1.0))
        return b

    colour = (0.3, 0.3, 0.3, 1.0)
    frames = {}
    for name, material in (("map", None), ("rough", Material(color=colour, metallic=0.0, roughness=230 / 255)),
                           ("metal", Material(color=colour, metallic=1.0, roughness=51 / 255))):
        runner = scene(build(material), (96, 96))
        frames[name] = linear_frame(runner)
        left, right = region(runner, (0.05, 0.42), (0.05, 0.95)), region(runner, (0.58, 0.95), (0.05, 0.95))
        runner.close()
    np.testing.assert_allclose(frames["map"][left], frames["rough"][left], atol=0.01)
    np.testing.assert_allclose(frames["map"][right], frames["metal"][right], atol=0.01)
    # The two materials differ where compared, so a map that did nothing would fail.
    assert np.abs(frames["rough"][right] - frames["metal"][right]).max() > 0.1
    assert np.abs(frames["rough"][left] - frames["metal"][left]).max() > 0.05


# --- OBJ / MTL -------------------------------------------------------------------------------

RAMP_STEP = 6  # grey levels a texel along u: a height slope of 6 / 255 a texel


def ramp() -> np.ndarray:
    """A 32 x 32 grey height map rising towards +U (the right of the image)."""
    row = (3 + RAMP_STEP * np.arange(32)).astype(np.uint8)
    return np.repeat(np.tile(row, (32, 1))[..., None], 3, axis=2)


def test_a_grey_map_bump_is_a_height_map_turned_into_normals(tmp_path):
    path = write_obj(tmp_path, quad(), "Kd 0.7 0.7 0.7\nmap_Bump -bm 8 -o 0 0 0 ramp.png", {"ramp.png": ramp()})
    (part,) = load_model(path)
    assert part.normal_scale == 8.0
    k = RAMP_STEP / 255.0  # the slope along u: the normal leans towards -U
    expected = np.array([-k, 0.0, 1.0]) / math.hypot(k, 1.0)
    # Every texel, the edges too (one-sided differences there: the ramp's slope all the same).
    normals = part.normal_map.pixels[..., :3].reshape(-1, 3).astype(np.float64) / 65535.0 * 2.0 - 1.0
    np.testing.assert_allclose(normals, np.tile(expected, (len(normals), 1)), atol=2e-4)


def test_an_mtl_norm_map_is_the_files_normal_map(tmp_path):
    tilt = np.tile(np.array([128, 170, 233], np.uint8), (4, 4, 1))
    (part,) = load_model(write_obj(tmp_path, quad(), "Kd 0.7 0.7 0.7\nnorm -bm 0.5 tilt.png", {"tilt.png": tilt}))
    np.testing.assert_array_equal(part.normal_map.pixels[..., :3], tilt)
    assert part.normal_scale == 0.5


@pytest.mark.parametrize("statement", ["map_Bump -bm 8 ramp.png", "bump -bm 8 ramp.png"])
def test_an_obj_bump_map_bends_the_light_as_the_turned_quad(scene, tmp_path, statement):
    """The height ramp's slope k, scaled by -bm, turns the normal by atan(8 k) towards -U:
    the loaded quad shades as a plain quad turned that way (real geometry, no map)."""
    path = write_obj(tmp_path, quad(), f"Kd 0.7 0.7 0.7\nPr 1.0\n{statement}", {"ramp.png": ramp()})
    angle = math.atan(8.0 * RAMP_STEP / 255.0)

    def build(turned: bool | None):
        def b(world):
            world.spawn(Transform(position=(0.0, 0.0, 2.5)), Camera(fov_y=50.0))
            world.spawn(DirectionalLight(direction=(-0.8, 0.0, -0.6), intensity=2.5))
            if turned is None:
                spawn_model(world, path)
            else:
                world.spawn(Transform(rotation=glm.angleAxis(-angle if turned else 0.0, glm.vec3(0, 1, 0))),
                            MeshRef(quad()), Material(color=(0.7, 0.7, 0.7), roughness=1.0))
        return b

    colours = {}
    for turned in (None, True, False):
        runner = scene(build(turned), (64, 64))
        runner.frame()
        rgb = runner.frame()
        col, row = runner.project((0.0, 0.0, 0.0))
        colours[turned] = rgb[row - 1:row + 2, col - 1:col + 2].reshape(-1, 3).astype(float).mean(axis=0)
        runner.close()
    np.testing.assert_allclose(colours[None], colours[True], atol=3.0)
    assert np.abs(colours[None] - colours[False]).max() > 12.0, colours  # the bump does something


def test_an_obj_map_ke_glows_at_ke(tmp_path):
    (part,) = load_model(write_obj(tmp_path, quad(), "Kd 0.5 0.5 0.5\nKe 2 2 2\nmap_Ke glow.png",
                                   {"glow.png": EMISSIVE}))
    np.testing.assert_array_equal(part.emissive_map.pixels[..., :3], EMISSIVE)
    assert part.emissive_factor == 2.0


@pytest.mark.parametrize("mtl, message", [
    ("Kd 1 1 1\nmap_Bump -bm 2 missing.png", r"model\.mtl'.*line 3: map_Bump: its image 'missing\.png' does not exist"),
    ("Kd 1 1 1\nnorm gone.png", r"model\.mtl'.*line 3: norm: its image 'gone\.png' does not exist"),
    ("Kd 1 1 1\nbump -bm lots ramp.png", r"model\.mtl'.*line 3: bump: -bm \(the bump scale\) must be a number"),
    ("Kd 1 1 1\nmap_Ke", r"model\.mtl'.*line 3: map_Ke: names no file"),
])
def test_a_bad_map_statement_names_the_library_and_line(tmp_path, mtl, message):
    path = write_obj(tmp_path, quad(), mtl, {"ramp.png": ramp()})
    with pytest.raises(AssetError, match=message):
        load_model(path)


# --- a curved reflective part gets a probe ------------------------------------------------------

def test_a_curved_reflective_part_reflects_its_probes_capture_not_only_the_sky(scene, tmp_path):
    """A metallic sphere from a GLB, a wall on its +X side that glows red through its emissive
    map (its diffuse colour is grey: the capture must draw the map too): the sphere's pixels
    whose reflected ray goes towards +X are red (the wall, as the probe captured it); the
    same sphere made to reflect only the sky (what spawn_model gave before) shows no red
    there."""
    path = write_glb(tmp_path / "ball.glb", sphere(0.6, 48, 24), {"pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.0}}, [])
    found = {}

    def build(sky_only: bool):
        def b(world):
            world.spawn(Skybox())
            look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=40.0)
            root = spawn_model(world, path)
            (found["ball"],) = [e for e, (t,) in world.query(Transform) if t.parent == root]
            if sky_only:
                world.get(found["ball"], Reflective).mode = "skybox"
            wall = glm.angleAxis(-glm.pi() / 2, glm.vec3(0, 1, 0))
            world.spawn(Transform(position=(1.6, 0.0, 0.0), rotation=wall),
                        MeshRef(quad(12, 12)), Emissive(1.5),
                        Material(color=(0.5, 0.5, 0.5), emissive_map=TextureData(np.full((4, 4, 3), (240, 20, 20),
                                                                                         np.uint8), "red glow")))
        return b

    redness = {}
    for sky_only in (False, True):
        runner = scene(build(sky_only), (96, 72))
        rgb = srgb_to_linear(runner.frame())
        if not sky_only:
            assert runner.stats.probe_captures == 1  # the part's own probe, captured before the main view
        ball = runner.ids() == found["ball"]
        # The right-hand third of the ball faces +X: its reflections go towards the wall.
        cols = np.flatnonzero(ball.any(axis=0))
        side = ball.copy()
        side[:, : cols[0] + 2 * (cols[-1] - cols[0]) // 3] = False
        side[: ball.shape[0] // 3] = side[2 * ball.shape[0] // 3:] = False
        pixels = rgb[side]
        assert len(pixels) > 20
        redness[sky_only] = float(np.mean(pixels[:, 0] > pixels[:, 1] + 0.15))
        runner.close()
    assert redness[False] > 0.8 and redness[True] < 0.1, redness


# --- level files and GPU resources -------------------------------------------------------------

def test_level_files_name_emissive_and_metallic_roughness_maps_and_save_them(tmp_path):
    import png

    mr16 = np.zeros((4, 4, 3), np.uint16)
    mr16[..., 1] = 40000
    mr16[..., 2] = np.arange(4, dtype=np.uint16)[None, :] * 9001
    with open(tmp_path / "mr16.png", "wb") as f:
        png.Writer(4, 4, greyscale=False, bitdepth=16).write(f, mr16.reshape(4, -1).tolist())
    Image.fromarray(EMISSIVE).save(tmp_path / "glow.png")
    text = """[level]
name = "maps"

[[entity]]
name = "lamp"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [1.0, 1.0] }
[entity.Material]
emissive_map = { file = "glow.png" }
metallic_roughness_map = { file = "mr16.png" }
[entity.Emissive]
power = 2.0
"""
    (tmp_path / "maps.toml").write_text(text)
    world = World("maps")
    try:
        names = load_level(tmp_path / "maps.toml").spawn(world)
        material = world.get(names["lamp"], Material)
        np.testing.assert_array_equal(material.emissive_map.pixels, rgba(EMISSIVE))
        assert material.metallic_roughness_map.pixels.dtype == np.uint16  # a linear map keeps 16 bits
        np.testing.assert_array_equal(material.metallic_roughness_map.pixels[..., :3], mr16)
        saved = save_level(world, tmp_path / "saved.toml", names, name="maps").read_text()
        assert 'emissive_map = { file = "glow.png" }' in saved
        assert 'metallic_roughness_map = { file = "mr16.png" }' in saved
    finally:
        world.close()


def test_a_bad_map_value_is_refused_naming_the_field():
    from components import ComponentValueError

    with pytest.raises(ComponentValueError, match="Material.emissive_map must be an engine.assets.texture_data"):
        Material(emissive_map=np.zeros((4, 4, 4), np.uint8))
    with pytest.raises(ComponentValueError, match="Material.metallic_roughness_map must be"):
        Material(metallic_roughness_map="mr.png")


def test_the_maps_gpu_textures_go_with_their_entity(scene, tmp_path):
    (part,) = load_model(pbr_glb(tmp_path / "painted.glb", sphere(0.5, 16, 8)))
    found = {}

    def build(world):
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0))
        (found["ball"],) = spawn_parts(world, [part])
        world.add_component(found["ball"], Emissive(1.0))

    runner = scene(build, (48, 48))
    runner.frame()
    renderer = runner.engine.renderer
    assert renderer.resource_counts()["textures"] == 3  # emissive, normal and metallic-roughness maps
    runner.world.delete_entity(found["ball"])
    runner.frame()
    assert renderer.resource_counts()["textures"] == 0 and renderer.resource_counts()["batches"] == 0


@pytest.mark.parametrize("strength, expected", [(None, 2.0), (5.0, 10.0)])
def test_gltf_emissive_strength_raises_the_glow_past_the_factor(tmp_path, strength, expected):
    """KHR_materials_emissive_strength (Blender writes it for a lamp brighter than 1)
    multiplies the emissive factor: with a grey 0.5 base, a white emissive factor is
    Emissive(2) alone and Emissive(10) at strength 5; with an emissive map, the map's
    strength is the factor's times it."""
    material = {"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]},
                "emissiveFactor": [1.0, 1.0, 1.0]}
    extra = {}
    if strength is not None:
        material["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}
        extra = {"extensionsUsed": ["KHR_materials_emissive_strength"],
                 "extensionsRequired": ["KHR_materials_emissive_strength"]}   # read: not refused
    world = World()
    root = spawn_model(world, write_glb(tmp_path / "lamp.glb", quad(1.0, 1.0), material, [], extra))
    (part,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
    assert world.get(part, Emissive).power == pytest.approx(expected, rel=1e-2)   # (the base kept as bytes)
    mapped = dict(material, emissiveTexture={"index": 0})
    (mapped_part,) = load_model(write_glb(tmp_path / "mapped.glb", quad(1.0, 1.0), mapped, [EMISSIVE], extra))
    assert mapped_part.emissive_factor == pytest.approx(1.0 if strength is None else strength)


def test_a_bad_gltf_emissive_strength_is_refused_naming_the_material(tmp_path):
    material = {"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]},
                "emissiveFactor": [1.0, 1.0, 1.0],
                "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -2}}}
    with pytest.raises(AssetError, match=r"lamp.*emissiveStrength must be a number in \[0, 10000\], got -2"):
        load_model(write_glb(tmp_path / "lamp.glb", quad(1.0, 1.0), material, []))



def glowing_model(path: Path):
    """A world-builder: the model at ``path`` 2 m ahead of the camera, every part glowing its
    own colour (no light: each shows its texture's colour)."""
    def build(world):
        look_from(world, (0.0, 1.0, 2.0), (0.0, 1.0, 0.0))
        spawn_model(world, path, position=(0.0, 1.0, 0.0))
        for entity, _ in list(world.query_one(Material)):
            if not world.has(entity, Emissive):
                world.add_component(entity, Emissive(1.0))
    return build


@pytest.mark.parametrize("transform, seen", [({"scale": [0.5, 1.0]}, (255, 0, 0)),
                                             ({"offset": [0.5, 0.0], "scale": [0.5, 0.5]}, (0, 0, 255)),
                                             ({"offset": [0.5, 0.5], "scale": [0.5, 0.5]}, (0, 255, 0))])
def test_gltf_texture_transform_shared_by_a_materials_maps_is_baked_into_its_uvs(scene, tmp_path, transform, seen):
    """KHR_texture_transform's offset and scale (an atlas's region), the same on every map
    of a material, move the UVs.  On an atlas red on its left half, blue on its right
    half's top and green on its bottom (glTF's v runs down the image), a quad showing the
    left half is red all over, the top right quarter blue and the bottom right green."""
    pixels = np.zeros((8, 8, 3), np.uint8)
    pixels[:, :4] = (255, 0, 0)
    pixels[:4, 4:] = (0, 0, 255)
    pixels[4:, 4:] = (0, 255, 0)
    material = {"name": "atlas", "pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": transform}}}}
    path = write_glb(tmp_path / "atlas.glb", quad(2.0, 2.0), material, [pixels],
                     {"extensionsUsed": ["KHR_texture_transform"]})
    (part,) = load_model(path)
    uv = part.mesh.uvs   # the quad's corners: u from the scale and offset; v the same, flipped (engine: up)
    np.testing.assert_allclose(uv[:, 0], quad(2.0, 2.0).uvs[:, 0] * transform["scale"][0]
                               + transform.get("offset", [0.0, 0.0])[0])

    runner = scene(glowing_model(path), (64, 48))
    frame = runner.frame()
    middle = frame[18:30, 26:38].reshape(-1, 3).astype(int)   # well inside the quad
    expected = np.array(seen)
    assert (np.abs(middle - expected * (middle.max(axis=1, keepdims=True) / 255.0)).max(axis=1) < 40).all(), \
        middle[:4]


def test_gltf_texture_transform_rotation_turns_the_image_as_the_extensions_example_says(scene, tmp_path):
    """KHR_texture_transform's own example: offset (0, 1), rotation a quarter turn and scale
    0.5 "utilize only the lower left quadrant of the source image, rotated clockwise 90
    degrees".  That quadrant holds four colours (red top left, green top right, blue
    bottom left, white bottom right); turned clockwise, the quad shows blue top left, red
    top right, white bottom left and green bottom right.  The rest of the image is grey,
    so the wrong quadrant (or the turn the other way) shows grey or the colours swapped."""
    pixels = np.full((8, 8, 3), 128, np.uint8)
    pixels[4:6, 0:2], pixels[4:6, 2:4] = (255, 0, 0), (0, 255, 0)
    pixels[6:8, 0:2], pixels[6:8, 2:4] = (0, 0, 255), (255, 255, 255)
    transform = {"offset": [0.0, 1.0], "rotation": math.pi / 2, "scale": [0.5, 0.5]}
    material = {"name": "turned", "pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": transform}}}}
    path = write_glb(tmp_path / "turned.glb", quad(2.0, 2.0), material, [pixels],
                     {"extensionsUsed": ["KHR_texture_transform"]})

    runner = scene(glowing_model(path), (64, 48))
    runner.engine.renderer.antialias = "off"
    frame = runner.frame().astype(int)
    # the quad spans about 0.58 of the view (2 m at 2 m, 60 degrees): its quarters' middles
    h, w = frame.shape[:2]
    quarter = round(0.58 * h / 4)
    for (dy, dx), colour in {(-1, -1): (0, 0, 255), (-1, 1): (255, 0, 0), (1, -1): (255, 255, 255),
                             (1, 1): (0, 255, 0)}.items():
        y, x = h // 2 + dy * quarter, w // 2 + dx * quarter
        seen = frame[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3)
        expected = np.array(colour) * (seen.max() / 255.0)
        assert np.abs(seen - expected).max() < 40, ((dy, dx), seen[:2])


def test_gltf_texture_transform_rotation_turns_the_uvs_counter_clockwise_with_v_down(tmp_path):
    """"Rotate the UVs by this many radians counter-clockwise around the origin" in glTF's
    UV space, v running down the image: the quad's u edge, (1, 0) untransformed, becomes
    scale x (cos r, -sin r) there (turned towards the image's top), its v edge scale x
    (sin r, cos r), and the corner at the origin moves by the offset alone."""
    r, scale, offset = 0.4, 0.7, (0.2, 0.1)
    material = {"name": "turned", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "extensions": {
        "KHR_texture_transform": {"offset": list(offset), "rotation": r, "scale": [scale, scale]}}}}}
    flat = quad(2.0, 2.0)
    path = write_glb(tmp_path / "turned.glb", flat, material, [np.full((4, 4, 3), 200, np.uint8)])
    (part,) = load_model(path)

    def gltf_uv(uvs: np.ndarray) -> np.ndarray:
        return np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1)   # the engine's v runs up

    before, after = gltf_uv(flat.uvs), gltf_uv(part.mesh.uvs)
    origin = int(np.argmin(np.abs(before).sum(axis=1)))
    along_u = int(np.argmin(np.abs(before - (1.0, 0.0)).sum(axis=1)))
    along_v = int(np.argmin(np.abs(before - (0.0, 1.0)).sum(axis=1)))
    np.testing.assert_allclose(after[origin], offset, atol=1e-6)
    np.testing.assert_allclose(after[along_u] - after[origin], scale * np.array([math.cos(r), -math.sin(r)]), atol=1e-6)
    np.testing.assert_allclose(after[along_v] - after[origin], scale * np.array([math.sin(r), math.cos(r)]), atol=1e-6)


@pytest.mark.parametrize("change, message", [
    ({"emissiveFactor": [1.0, -0.5, 0.0]}, r"material 'bad': emissiveFactor must be three numbers in \[0, 65504\]"),
    ({"emissiveFactor": [1.0, 1.0]}, r"material 'bad': emissiveFactor must be three numbers"),
    ({"transform": {"offset": [0.5]}},
     r"material 'bad': baseColorTexture: KHR_texture_transform\.offset must be 2 finite numbers, got \[0\.5\]"),
    ({"transform": {"rotation": "quarter"}},
     r"material 'bad': baseColorTexture: KHR_texture_transform\.rotation must be 1 finite number, got 'quarter'"),
    ({"transform": {"scale": [1.0, 1e9]}},
     r"material 'bad': baseColorTexture: KHR_texture_transform\.scale must be 2 finite numbers"),
    ({"transform": [0.5, 0.5]},
     r"material 'bad': baseColorTexture: KHR_texture_transform must be an object, got \[0\.5, 0\.5\]"),
], ids=["a negative emission", "two emission numbers", "a one-number offset", "a word for a rotation",
        "a scale past 1e6", "a list for a transform"])
def test_a_malformed_emission_or_texture_transform_is_refused_naming_the_material_and_map(tmp_path, change,
                                                                                         message):
    """A file's emissiveFactor and KHR_texture_transform are checked as they are read: one
    written wrong is an error naming the file, the material and (a transform) the map, not
    a glow or UVs made of it."""
    material = {"name": "bad", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0],
                                                        "baseColorTexture": {"index": 0}}}
    if "transform" in change:
        material["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
            "KHR_texture_transform": change["transform"]}
    else:
        material.update(change)
    path = write_glb(tmp_path / "bad.glb", quad(1.0, 1.0), material, [np.full((4, 4, 3), 128, np.uint8)],
                     {"extensionsUsed": ["KHR_texture_transform"]})
    with pytest.raises(AssetError, match=rf"bad\.glb': {message}"):
        load_model(path)
