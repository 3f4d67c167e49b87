"""glTF's normalised integer accessors (core glTF's packed UVs and colours, and
``KHR_mesh_quantization``'s packed normals and coordinates) are read as the numbers they
stand for: each file here stores a quad's known float values as bytes or shorts, and the
loaded mesh must hold the floats back (to the integers' step), including an interleaved
view and a quantized mesh moved into place by its node's scale, as gltfpack writes one."""
from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from engine.assets.mesh import load_model, quad
from engine.core.errors import AssetError
from tests.test_materials_from_files import png_bytes

MATERIAL = {"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0]}}


class GlbWriter:
    """A GLB of one node and one primitive from accessors given as raw arrays."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, stride: int | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.views.append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data),
                           **({"byteStride": stride} if stride else {})})
        self.blob.extend(data)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, kind: str, component: int, view: int | None = None, offset: int = 0,
                 **extra) -> int:
        self.accessors.append({"bufferView": self.view(array.tobytes()) if view is None else view,
                               "byteOffset": offset, "componentType": component, "count": len(array), "type": kind,
                               **extra})
        return len(self.accessors) - 1

    def write(self, path: Path, attributes: dict, indices: np.ndarray, node: dict | None = None,
              extra: dict | None = None, material: dict | None = None) -> Path:
        doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
               "nodes": [{"mesh": 0, **(node or {})}],
               "meshes": [{"primitives": [{"attributes": attributes, "material": 0,
                                           "indices": self.accessor(indices.astype(np.uint32).ravel(), "SCALAR",
                                                                    5125)}]}],
               "materials": [material or MATERIAL], "accessors": self.accessors, "bufferViews": self.views,
               "buffers": [{"byteLength": len(self.blob)}], **(extra or {})}
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        while len(self.blob) % 4:
            self.blob.append(0)
        body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(self.blob), b"BIN\0") \
            + bytes(self.blob)
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return path


def gltf_uvs(mesh) -> np.ndarray:
    uv = mesh.uvs.astype(np.float64).copy()
    uv[:, 1] = 1.0 - uv[:, 1]   # glTF's v runs down
    return uv


FLAT = quad(2.0, 2.0)
UVS = np.array([[0.1, 0.9], [0.6, 0.9], [0.6, 0.4], [0.1, 0.4]])   # glTF's (v down)
COLOURS = np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 1.0, 1.0], [0.5, 0.5, 0.5, 1.0]])


def float_positions(writer: GlbWriter) -> int:
    positions = FLAT.positions.astype(np.float32)
    return writer.accessor(positions, "VEC3", 5126, min=positions.min(0).tolist(), max=positions.max(0).tolist())


def test_normalized_short_uvs_and_byte_colours_are_read_as_the_floats_they_stand_for(tmp_path):
    writer = GlbWriter()
    attributes = {"POSITION": float_positions(writer),
                  "TEXCOORD_0": writer.accessor(np.round(UVS * 65535).astype(np.uint16), "VEC2", 5123,
                                                normalized=True),
                  "COLOR_0": writer.accessor(np.round(COLOURS * 255).astype(np.uint8), "VEC4", 5121,
                                             normalized=True)}
    (part,) = load_model(writer.write(tmp_path / "packed.glb", attributes, FLAT.indices))
    np.testing.assert_allclose(gltf_uvs(part.mesh), UVS, atol=1.0 / 65535 + 1e-6)
    np.testing.assert_allclose(part.mesh.colors, COLOURS, atol=1.0 / 255 + 1e-6)   # (an alpha below 1: RGBA)


def test_an_interleaved_view_of_normalized_values_is_read_by_its_stride(tmp_path):
    """UVs as unsigned bytes and normals as signed bytes in one view, eight bytes a vertex."""
    writer = GlbWriter()
    packed = np.zeros((4, 8), np.uint8)
    packed[:, 0:2] = np.round(UVS * 255).astype(np.uint8)
    normals = np.tile(np.array([0, 0, 127], np.int8), (4, 1))
    packed[:, 4:7] = normals.view(np.uint8)
    view = writer.view(packed.tobytes(), stride=8)
    attributes = {"POSITION": float_positions(writer),
                  "TEXCOORD_0": writer.accessor(packed[:, :2], "VEC2", 5121, view=view, normalized=True),
                  "NORMAL": writer.accessor(normals, "VEC3", 5120, view=view, offset=4, normalized=True)}
    path = writer.write(tmp_path / "interleaved.glb", attributes, FLAT.indices,
                        extra={"extensionsUsed": ["KHR_mesh_quantization"],
                               "extensionsRequired": ["KHR_mesh_quantization"]})
    (part,) = load_model(path)
    np.testing.assert_allclose(gltf_uvs(part.mesh), UVS, atol=1.0 / 255 + 1e-6)
    np.testing.assert_allclose(part.mesh.normals, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-6)


def test_a_quantized_mesh_as_gltfpack_writes_it(tmp_path):
    """Positions as plain shorts placed by the node's scale and offset, normals as normalised
    bytes, UVs as normalised shorts brought back by KHR_texture_transform."""
    writer = GlbWriter()
    lo, hi = FLAT.positions.min(0), FLAT.positions.max(0)
    step = float((hi - lo).max()) / 1023.0
    shorts = np.round((FLAT.positions - lo) / step).astype(np.int16)
    shorts4 = np.zeros((4, 4), np.int16)   # (glTF: a vertex attribute's elements start on 4 bytes)
    shorts4[:, :3] = shorts
    position_view = writer.view(shorts4.tobytes(), stride=8)
    uv_lo, uv_size = UVS.min(0), UVS.max(0) - UVS.min(0)
    uv_shorts = np.round((UVS - uv_lo) / uv_size * 65535).astype(np.uint16)
    attributes = {"POSITION": writer.accessor(shorts, "VEC3", 5122, view=position_view,
                                              min=shorts.min(0).tolist(), max=shorts.max(0).tolist()),
                  "NORMAL": writer.accessor(np.tile(np.array([0, 0, 127, 0], np.int8), (4, 1))[:, :3].copy(),
                                            "VEC3", 5120, normalized=True),
                  "TEXCOORD_0": writer.accessor(uv_shorts, "VEC2", 5123, normalized=True)}
    material = {"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "baseColorTexture": {
        "index": 0, "extensions": {"KHR_texture_transform": {"offset": uv_lo.tolist(), "scale": uv_size.tolist()}}}}}
    image_view = writer.view(png_bytes(np.full((4, 4, 3), 200, np.uint8)))
    path = writer.write(tmp_path / "quantized.glb", attributes, FLAT.indices,
                        node={"translation": lo.tolist(), "scale": [step] * 3}, material=material,
                        extra={"images": [{"bufferView": image_view, "mimeType": "image/png"}],
                               "textures": [{"source": 0}],
                               "extensionsUsed": ["KHR_mesh_quantization", "KHR_texture_transform"],
                               "extensionsRequired": ["KHR_mesh_quantization"]})
    (part,) = load_model(path)
    matrix = np.array(part.local, np.float64)   # (numpy reads a glm.mat4 as the matrix: points are columns)
    placed = part.mesh.positions @ matrix[:3, :3].T + matrix[:3, 3]
    np.testing.assert_allclose(placed, FLAT.positions, atol=step)
    np.testing.assert_allclose(part.mesh.normals, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-6)
    np.testing.assert_allclose(gltf_uvs(part.mesh), UVS, atol=1e-4)


@pytest.mark.parametrize("change, message", [
    ({"componentType": 5126}, r"accessor 1: normalized is only for byte and short components"),
    ({"count": 40}, r"accessor 1: its 40 elements run past the end of bufferView 1"),
    ({"bufferView": 9}, r"accessor 1: names bufferView 9, which the file does not have"),
])
def test_a_normalized_accessor_that_cannot_be_read_is_refused_naming_it(tmp_path, change, message):
    writer = GlbWriter()
    attributes = {"POSITION": float_positions(writer),
                  "TEXCOORD_0": writer.accessor(np.round(UVS * 65535).astype(np.uint16), "VEC2", 5123,
                                                normalized=True)}
    writer.accessors[1].update(change)
    with pytest.raises(AssetError, match=rf"bad\.glb.*{message}"):
        load_model(writer.write(tmp_path / "bad.glb", attributes, FLAT.indices))


@pytest.mark.parametrize("kind", ["webp", "avif"])
def test_a_webp_or_avif_texture_is_read_in_place_of_its_fallback(tmp_path, kind):
    """EXT_texture_webp and EXT_texture_avif: the texture's WebP or AVIF image (lossless) is
    the one read, its PNG "source" only a fallback; a texture with that image alone reads it
    too."""
    import io

    from PIL import Image, features

    if not features.check(kind):
        pytest.skip(f"this Pillow decodes no {kind.upper()} (EXT_texture_{kind} files are refused by it)")
    webp_pixels = np.zeros((16, 16, 3), np.uint8)
    webp_pixels[:, :8] = (200, 30, 30)
    webp_pixels[:, 8:] = (30, 30, 200)
    out = io.BytesIO()
    Image.fromarray(webp_pixels).save(out, format=kind.upper(), lossless=True)
    for fallback in (True, False):
        writer = GlbWriter()
        webp_view = writer.view(out.getvalue())
        images = [{"bufferView": webp_view, "mimeType": f"image/{kind}"}]
        texture: dict = {"extensions": {f"EXT_texture_{kind}": {"source": 0}}}
        if fallback:
            images.append({"bufferView": writer.view(png_bytes(np.full((4, 4, 3), 90, np.uint8))),
                           "mimeType": "image/png"})
            texture["source"] = 1
        material = {"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                          "baseColorTexture": {"index": 0}}}
        path = writer.write(tmp_path / "webp.glb",
                            {"POSITION": float_positions(writer), "TEXCOORD_0": writer.accessor(
                                gltf_uvs(FLAT).astype(np.float32), "VEC2", 5126)}, FLAT.indices, material=material,
                            extra={"images": images, "textures": [texture],
                                   "extensionsUsed": [f"EXT_texture_{kind}"],
                                   "extensionsRequired": [] if fallback else [f"EXT_texture_{kind}"]})
        (part,) = load_model(path)
        if kind == "webp":
            np.testing.assert_array_equal(part.texture.pixels[..., :3], webp_pixels)
        else:  # (AVIF's "lossless" goes through YUV: exact away from the edge, within a few levels)
            away = np.r_[0:5, 11:16]
            assert np.abs(part.texture.pixels[:, away, :3].astype(int) - webp_pixels[:, away]).max() <= 6


# --- sparse accessors, and accessors past the bytes a file holds ------------------------------

MOVED = np.array([[1.0, 1.5, 0.25]], np.float32)   # vertex 2's place, stored sparsely


def sparse_of(writer: GlbWriter, indices: np.ndarray, values: np.ndarray, index_type: int) -> dict:
    return {"count": len(indices),
            "indices": {"bufferView": writer.view(indices.tobytes()), "componentType": index_type},
            "values": {"bufferView": writer.view(values.tobytes())}}


def test_a_sparse_accessor_is_read_as_its_base_with_the_stored_elements_put_in(tmp_path):
    """glTF's sparse accessors outside morph targets: positions with a base view and vertex 2
    stored sparsely, positions with no base (zeros but for vertices 1 and 3), and normalised
    short UVs with vertex 0's stored sparsely (made dense, then read as the floats they stand
    for); each loaded array is the base with those rows replaced, written out here with numpy."""
    writer = GlbWriter()
    positions = float_positions(writer)
    writer.accessors[positions]["sparse"] = sparse_of(writer, np.array([2], np.uint16), MOVED, 5123)
    writer.accessors[positions]["max"] = [1.0, 1.5, 0.25]
    uv_shorts = np.round(UVS * 65535).astype(np.uint16)
    uvs = writer.accessor(uv_shorts, "VEC2", 5123, normalized=True)
    writer.accessors[uvs]["sparse"] = sparse_of(writer, np.array([0], np.uint32), np.array([[65535, 0]], np.uint16),
                                                5125)
    (part,) = load_model(writer.write(tmp_path / "sparse.glb", {"POSITION": positions, "TEXCOORD_0": uvs},
                                      FLAT.indices))
    expected = FLAT.positions.copy()
    expected[2] = MOVED[0]
    np.testing.assert_array_equal(part.mesh.positions, expected)
    expected_uvs = uv_shorts / 65535.0
    expected_uvs[0] = (1.0, 0.0)
    np.testing.assert_allclose(gltf_uvs(part.mesh), expected_uvs, atol=1e-6)

    writer = GlbWriter()
    writer.accessors.append({"componentType": 5126, "count": 4, "type": "VEC3", "min": [-1.0, -1.0, 0.0],
                             "max": [1.0, 1.0, 0.0],
                             "sparse": sparse_of(writer, np.array([1, 3], np.uint8),
                                                 FLAT.positions[[1, 3]].astype(np.float32), 5121)})
    (part,) = load_model(writer.write(tmp_path / "zeros.glb", {"POSITION": 0}, FLAT.indices))
    expected = np.zeros((4, 3))
    expected[[1, 3]] = FLAT.positions[[1, 3]]
    np.testing.assert_array_equal(part.mesh.positions, expected)


@pytest.mark.parametrize("indices, count, message", [
    ([2, 1], 2, r"accessor 0: sparse\.indices must increase and lie in 0\.\.3"),
    ([1, 4], 2, r"accessor 0: sparse\.indices must increase and lie in 0\.\.3"),
    ([0, 1, 2, 3, 3], 5, r"accessor 0: sparse\.count must be an integer in 1\.\.4, got 5"),
], ids=["decreasing", "past the count", "more than the count"])
def test_a_sparse_accessor_that_cannot_be_read_is_refused_naming_it(tmp_path, indices, count, message):
    writer = GlbWriter()
    positions = float_positions(writer)
    writer.accessors[positions]["sparse"] = sparse_of(writer, np.array(indices, np.uint16),
                                                      np.zeros((len(indices), 3), np.float32), 5123)
    writer.accessors[positions]["sparse"]["count"] = count
    with pytest.raises(AssetError, match=rf"bad\.glb.*{message}"):
        load_model(writer.write(tmp_path / "bad.glb", {"POSITION": positions}, FLAT.indices))


def cut_short(path: Path, how: str) -> Path:
    """The plain quad's GLB spoilt as ``how`` says (its JSON kept unless a .gltf is made)."""
    data = path.read_bytes()
    json_length = struct.unpack("<I", data[12:16])[0]
    doc, binary = json.loads(data[20:20 + json_length]), data[20 + json_length + 8:]
    if how == "truncated":   # (the last bytes lost in a copy)
        path.write_bytes(data[:-30])
    elif how == "header":
        path.write_bytes(data[:10])
    elif how == "no binary chunk":   # (its header's length made to fit, the buffer without a uri)
        kept = data[:20 + json_length]
        path.write_bytes(kept[:8] + struct.pack("<I", len(kept)) + kept[12:])
    else:
        if how == "short bin":
            (path.parent / "quad.bin").write_bytes(binary[:20])
        else:
            (path.parent / "quad.bin").write_bytes(binary)
            if how == "missing buffer":
                doc["bufferViews"][0]["buffer"] = 3
            else:   # "count past its view"
                doc["accessors"][0]["count"] = 40
        doc["buffers"][0]["uri"] = "quad.bin"
        path = path.with_suffix(".gltf")
        path.write_text(json.dumps(doc))
    return path


CUT_SHORT = [
    ("truncated", r"is cut short \(its GLB header says \d+ bytes, the file holds \d+\)"),
    ("header", r"is cut short \(its GLB header says 12 bytes, the file holds 10\)"),
    ("no binary chunk", r"accessor 0: its bufferView 0 reads buffer 0, whose bytes the file does not hold"),
    ("short bin", r"accessor 0: its bufferView 0 \(48 bytes at 0\) runs past the end of buffer 0, which holds 20 "
                  r"bytes \(the file is cut short\)"),
    ("missing buffer", r"accessor 0: its bufferView 0 names buffer 3, which the file does not have"),
    ("count past its view", r"accessor 0: its 40 elements run past the end of bufferView 0"),
]


@pytest.mark.parametrize("how, message", CUT_SHORT, ids=[case[0] for case in CUT_SHORT])
def test_a_file_cut_short_or_reading_past_its_bytes_is_refused_naming_the_accessor(tmp_path, how, message):
    """A GLB or .bin cut short, a GLB without its binary chunk, a view naming a buffer the file
    lacks, a count past its view: each refused naming the file, the accessor and why (trimesh,
    left to read them, fails with a bare IndexError, ValueError or AssertionError)."""
    writer = GlbWriter()
    path = writer.write(tmp_path / "quad.glb", {"POSITION": float_positions(writer)}, FLAT.indices)
    assert len(load_model(path)) == 1   # (whole, it loads)
    path = cut_short(path, how)
    with pytest.raises(AssetError, match=rf"quad\.gl(b|tf)': {message}"):
        load_model(path)
