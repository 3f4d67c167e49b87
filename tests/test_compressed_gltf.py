"""Compressed glTF (engine/assets/gltf_compression.py): a box coded by Draco
(``KHR_draco_mesh_compression``) loads as the box's triangles; a box whose vertex and index
views are packed by meshoptimizer (``EXT_meshopt_compression``, normals octahedral-filtered
bytes under ``KHR_mesh_quantization``) loads as the same box written plainly, and draws the same;
a texture as a Basis Universal KTX2 image (``KHR_texture_basisu``) reads as the picture it
was made from; a file only using the extensions keeps its fallback; one requiring them
without their package is refused naming it; malformed data is refused naming the view."""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from engine.assets import gltf_compression
from engine.assets.mesh import box, load_model_file
from engine.core.errors import AssetError
from tests.test_materials_from_files import write_glb

meshopt = pytest.importorskip("meshopt", reason="the meshopt package (pip install speculum[compressed]) is not "
                                                "installed: EXT_meshopt_compression cannot be read")

BOX = box((1.0, 0.6, 0.4))
MATERIAL = {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.3, 0.2, 1.0], "metallicFactor": 0.0}}


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(blob), b"BIN\0") + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def packed_box(path: Path, required: bool = True, fallback_data: bool = False, spoil: dict | None = None) -> Path:
    """The box with its positions (float), normals (octahedral-filtered signed bytes), UVs
    (float) and indices (uint32) each in a meshopt-packed view; the fallback buffer empty,
    or holding the plain data (``fallback_data``); ``spoil``: fields of the first view's
    extension made wrong."""
    uv = BOX.uvs.astype(np.float32).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    normals4 = np.hstack([BOX.normals, np.zeros((len(BOX.normals), 1))]).astype(np.float32)
    octahedral = meshopt.encode_filter_oct(normals4, 4, 8)
    plain = [(BOX.positions.astype(np.float32).view(np.uint8).reshape(-1, 12), "ATTRIBUTES", "NONE", 12),
             (octahedral.reshape(-1, 4), "ATTRIBUTES", "OCTAHEDRAL", 4),
             (uv.view(np.uint8).reshape(-1, 8), "ATTRIBUTES", "NONE", 8),
             (BOX.indices.astype(np.uint32).ravel(), "TRIANGLES", "NONE", 4)]
    blob, fallback, views = bytearray(), bytearray(), []
    for data, mode, filter_, stride in plain:
        packed = meshopt.encode_gltf_buffer(data, mode)
        while len(blob) % 4:
            blob.append(0)
        ext = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(packed), "byteStride": stride,
               "count": len(data), "mode": mode, **({"filter": filter_} if filter_ != "NONE" else {})}
        blob.extend(packed)
        views.append({"buffer": 1, "byteOffset": len(fallback), "byteLength": len(data) * stride,
                      **({"byteStride": stride} if mode == "ATTRIBUTES" else {}),
                      "extensions": {"EXT_meshopt_compression": ext}})
        # (the fallback holds the data as a loader reads it: the filter undone)
        fallback.extend(meshopt.decode_gltf_buffer(packed, len(data), stride, mode,
                                                   None if filter_ == "NONE" else filter_).tobytes())
    if spoil:
        views[0]["extensions"]["EXT_meshopt_compression"].update(spoil)
    count = len(BOX.positions)
    accessors = [{"bufferView": 0, "componentType": 5126, "count": count, "type": "VEC3",
                  "min": BOX.positions.min(0).tolist(), "max": BOX.positions.max(0).tolist()},
                 {"bufferView": 1, "componentType": 5120, "normalized": True, "count": count, "type": "VEC3"},
                 {"bufferView": 2, "componentType": 5126, "count": count, "type": "VEC2"},
                 {"bufferView": 3, "componentType": 5125, "count": BOX.indices.size, "type": "SCALAR"}]
    used = ["EXT_meshopt_compression", "KHR_mesh_quantization"]
    second = {"byteLength": len(fallback), "extensions": {"EXT_meshopt_compression": {"fallback": True}}}
    if fallback_data:
        second["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(fallback)).decode()
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3,
                                       "material": 0}]}],
           "materials": [MATERIAL], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob)}, second], "extensionsUsed": used,
           **({"extensionsRequired": used} if required else {})}
    path.write_bytes(glb_bytes(doc, bytes(blob)))
    return path


def same_mesh(loaded, reference) -> None:
    np.testing.assert_array_equal(loaded.positions, reference.positions)
    np.testing.assert_allclose(loaded.uvs, reference.uvs, atol=1e-6)
    np.testing.assert_array_equal(loaded.indices, reference.indices)
    np.testing.assert_allclose(loaded.normals, reference.normals, atol=0.02)   # (8-bit octahedral: about a degree)


def test_a_meshopt_packed_box_loads_as_the_box_written_plainly(tmp_path):
    (plain,) = load_model_file(write_glb(tmp_path / "plain.glb", BOX, MATERIAL, [])).parts
    (packed,) = load_model_file(packed_box(tmp_path / "packed.glb")).parts
    same_mesh(packed.mesh, plain.mesh)
    same_mesh(packed.mesh, BOX)


def test_a_meshopt_packed_box_draws_as_the_plain_one(scene, tmp_path):
    from components import DirectionalLight, Material, MeshRef, Transform
    from engine.assets.mesh import plane
    from engine.assets.models import spawn_model
    from tests.support import look_from

    def lit(path):
        def build(world):
            look_from(world, (1.5, 1.5, 3.0), (0.0, 0.3, 0.0))
            world.spawn(DirectionalLight(direction=(-0.4, -1.0, -0.6), intensity=2.0))
            world.spawn(Transform(), MeshRef(plane(6, 6)), Material())
            spawn_model(world, path, position=(0.0, 0.3, 0.0))
        return build

    def frame(path):
        runner = scene(lit(path), (160, 120))
        runner.frame()
        return runner.frame().astype(int)

    packed, plain = frame(packed_box(tmp_path / "packed.glb")), frame(write_glb(tmp_path / "plain.glb", BOX,
                                                                                MATERIAL, []))
    assert (np.abs(packed - plain).max(axis=-1) > 8).sum() <= 0.002 * packed[..., 0].size
    assert (packed[..., 0] > packed[..., 2] + 40).sum() > 300   # (the red box is there)


def test_without_the_decoder_a_requiring_file_is_refused_and_a_using_one_reads_its_fallback(tmp_path, monkeypatch):
    monkeypatch.setattr(gltf_compression, "_decoder", lambda extension: None)
    with pytest.raises(AssetError, match=r"requires the glTF extension.*EXT_meshopt_compression \(needs the meshopt "
                                         r"package: pip install meshopt\)"):
        load_model_file(packed_box(tmp_path / "packed.glb"))
    (part,) = load_model_file(packed_box(tmp_path / "fallback.glb", required=False, fallback_data=True)).parts
    same_mesh(part.mesh, BOX)


@pytest.mark.parametrize("spoil, message", [
    ({"mode": "POINTS"}, r"bufferView 0 \(EXT_meshopt_compression\): mode must be one of"),
    ({"byteStride": 6}, r"byteStride 6 does not suit mode ATTRIBUTES"),
    ({"byteLength": 10 ** 6}, r"its 1000000 bytes at 0 lie outside buffer 0"),
    ({"byteOffset": 4}, r"bufferView 0 \(EXT_meshopt_compression\): its data does not decode"),
    ({"count": -1}, r"count must be a whole number >= 0, got -1"),
    # refused before the decoder allocates 1.2 GB (the model fuzz's seed 10206, case 71: 39 s)
    ({"count": 10 ** 8}, r"count x byteStride is 1200000000 bytes, but the view's byteLength is 288"),
])
def test_malformed_packed_views_are_refused_naming_them(tmp_path, spoil, message):
    with pytest.raises(AssetError, match=message):
        load_model_file(packed_box(tmp_path / "bad.glb", spoil=spoil))


def test_a_ktx2_texture_reads_as_the_picture_it_was_made_from(tmp_path):
    """A 32x32 image of four colours (its top left red) as a UASTC KTX2 image the texture
    names through KHR_texture_basisu (no PNG source): the material's texture is the picture,
    the right way up; without the transcoder the file is refused naming alktx2."""
    alktx2 = pytest.importorskip("alktx2", reason="the alktx2 package is not installed: KHR_texture_basisu "
                                                  "cannot be read")
    pixels = np.zeros((32, 32, 4), np.uint8)
    pixels[..., 3] = 255
    pixels[:16, :16, :3] = (220, 30, 30)
    pixels[:16, 16:, :3] = (30, 200, 40)
    pixels[16:, :16, :3] = (30, 40, 210)
    pixels[16:, 16:, :3] = (230, 220, 40)
    ktx2 = alktx2.encode_raw_rgba_to_ktx2(pixels.tobytes(), 32, 32, has_alpha=False, codec="uastc")
    path = write_glb(tmp_path / "ktx.glb", BOX, {**MATERIAL, "pbrMetallicRoughness": {
        **MATERIAL["pbrMetallicRoughness"], "baseColorTexture": {"index": 0}}}, [pixels[..., :3].copy()])
    from tests.test_model_variants import edit_glb

    def to_ktx2(doc):
        doc["images"].append({"uri": "data:image/ktx2;base64," + base64.b64encode(ktx2).decode(),
                              "mimeType": "image/ktx2"})
        doc["textures"] = [{"extensions": {"KHR_texture_basisu": {"source": len(doc["images"]) - 1}}}]
        doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_texture_basisu"]
    edit_glb(path, to_ktx2)
    (part,) = load_model_file(path).parts
    got = part.texture.pixels.astype(int)
    for rows, cols in ((slice(2, 14), slice(2, 14)), (slice(2, 14), slice(18, 30)), (slice(18, 30), slice(2, 14)),
                       (slice(18, 30), slice(18, 30))):
        assert np.abs(got[rows, cols, :3] - pixels[rows, cols, :3]).max() <= 12
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(gltf_compression, "_decoder", lambda extension: None)
        with pytest.raises(AssetError, match=r"KHR_texture_basisu \(needs the alktx2 package"):
            load_model_file(path)


def draco_box(path: Path, required: bool = True, spoil: str = "") -> Path:
    """The box as one Draco-coded primitive (positions, normals, UVs and triangles), its
    accessors naming no view (the Draco data holds them); ``spoil`` "bytes": the Draco data
    scrambled, "id": an attribute naming an id the data lacks."""
    draco = pytest.importorskip("DracoPy", reason="the DracoPy package is not installed: KHR_draco_mesh_compression "
                                                  "cannot be read")
    uv = BOX.uvs.astype(np.float64).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    coded = bytearray(draco.encode(BOX.positions, BOX.indices.astype(np.uint32), quantization_bits=16,
                                   normals=BOX.normals.astype(np.float64), tex_coord=uv, preserve_order=True))
    ids = {a["attribute_type"]: a["unique_id"] for a in draco.decode(bytes(coded)).attributes}
    if spoil == "bytes":
        coded[len(coded) // 3:] = bytes(len(coded) - len(coded) // 3)
    names = {"POSITION": ids[0], "NORMAL": ids[1], "TEXCOORD_0": 99 if spoil == "id" else ids[3]}
    count = len(BOX.positions)
    accessors = [{"componentType": 5126, "count": count, "type": "VEC3", "min": BOX.positions.min(0).tolist(),
                  "max": BOX.positions.max(0).tolist()},
                 {"componentType": 5126, "count": count, "type": "VEC3"},
                 {"componentType": 5126, "count": count, "type": "VEC2"},
                 {"componentType": 5125, "count": BOX.indices.size, "type": "SCALAR"}]
    used = ["KHR_draco_mesh_compression"]
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3,
                                       "material": 0, "extensions": {"KHR_draco_mesh_compression": {
                                           "bufferView": 0, "attributes": names}}}]}],
           "materials": [MATERIAL], "accessors": accessors,
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(coded)}],
           "buffers": [{"byteLength": len(coded)}], "extensionsUsed": used,
           **({"extensionsRequired": used} if required else {})}
    path.write_bytes(glb_bytes(doc, bytes(coded)))
    return path


def corners(mesh) -> np.ndarray:
    """Each triangle's corners (position, normal, uv), rows sorted: the same triangles match
    whatever order a coder stores them in."""
    rows = np.hstack([mesh.positions[mesh.indices.ravel()], mesh.normals[mesh.indices.ravel()],
                      mesh.uvs[mesh.indices.ravel()]]).reshape(len(mesh.indices), -1)
    return rows[np.lexsort(np.round(rows, 3).T[::-1])]


def test_a_draco_coded_box_loads_as_the_box_written_plainly(tmp_path):
    (part,) = load_model_file(draco_box(tmp_path / "draco.glb")).parts
    np.testing.assert_allclose(corners(part.mesh), corners(BOX), atol=2e-3)   # (16-bit positions, Draco's normals)


@pytest.mark.parametrize("spoil, message", [("bytes", r"its data does not decode"),
                                            ("id", r"attribute TEXCOORD_0 \(Draco id 99\) is not in its Draco data")])
def test_a_damaged_draco_primitive_is_refused_naming_it(tmp_path, spoil, message):
    with pytest.raises(AssetError, match=rf"mesh 0's primitive 0 \(KHR_draco_mesh_compression\): {message}"):
        load_model_file(draco_box(tmp_path / "bad.glb", spoil=spoil))


def test_without_dracopy_a_draco_file_is_refused_naming_the_package(tmp_path, monkeypatch):
    path = draco_box(tmp_path / "draco.glb")
    monkeypatch.setattr(gltf_compression, "_decoder", lambda extension: None)
    with pytest.raises(AssetError, match=r"KHR_draco_mesh_compression \(needs the DracoPy package: pip install "
                                         r"DracoPy\)"):
        load_model_file(path)


def test_a_packed_view_past_the_asset_budget_is_refused_before_it_is_decoded(tmp_path):
    """A count that agrees with its view's byteLength but decodes past ASSET_MEMORY_BUDGET:
    refused naming the view, before the decoder allocates it."""
    from tests.test_model_variants import edit_glb

    path = packed_box(tmp_path / "huge.glb", spoil={"count": 10 ** 8})

    def agree(doc):
        doc["bufferViews"][0]["byteLength"] = 12 * 10 ** 8

    with pytest.raises(AssetError, match=r"bufferView 0 \(EXT_meshopt_compression\): decodes to 1200000000 bytes, "
                                         r"past the \d+-byte budget"):
        load_model_file(edit_glb(path, agree))
