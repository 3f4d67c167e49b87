"""Model fuzz: model files made at random, loaded with ``load_model`` and spawned with
``spawn_model`` outside any level, and rendered for ``FRAMES`` frames.

Each case writes an OBJ (with its MTL) or a GLB whose statements are drawn from adversarial
pools: faces whose indices refer forward, count back, pass the file's end, are 0 or text,
or name texture coordinates the file never gives; lines continued with a backslash; an
``mtllib`` in a comment or naming a FIFO; map statements (``map_Kd``, ``norm``,
``map_Bump``, ``bump``, ``map_Ke``) with options (``-s``, ``-o``, ``-bm``, ``-clamp``, an
unknown one) naming an image, a 16-bit or grey map, garbage, a FIFO, a directory, a symlink
loop, a missing file whose bare name is a FIFO, a file outside the model's folder; glTF
materials whose textures are missing, not images, ``data:`` URIs of either kind, indices
out of range; many chrome nodes of one mesh; skins (joints past the skin's, weights negative
or all zero, inverse bind matrices too few or not affine) and morph targets (sparse indices
past the vertices, weights too few, a clip playing them).  A case passes when ``load_model`` or
``spawn_model`` raises an ``AssetError`` naming the model's file (and the world is left as
it was), or the model spawns and ``FRAMES`` frames render with no NaN in the HDR target
and ``ctx.error`` clean.  Any other exception, or a case still running after
``CASE_SECONDS`` (a FIFO opened), is a failure.

    python -m benchmarks fuzz --model-cases 300
"""
from __future__ import annotations

import base64
import io
import json
import os
import random
import struct
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SIZE = (48, 32)


@dataclass
class ModelCase:
    kind: str                 # "obj" or "glb"
    files: dict[str, bytes]   # written beside the model (in the case's own folder)
    mutations: list[str] = field(default_factory=list)

    def describe(self) -> str:
        return f"{self.kind}: " + "; ".join(self.mutations)


# --- the shared files a case may name (in the fuzz folder's "shared" folder and "outside") -------

_IMAGES = ["good.png", "grey.png", "n16.png", "garbage.png", "fifo.png", "folder.png", "loop.png", "gone.png",
           "textures/fifo.png", "../outside/secret.png", "@OUTSIDE@/secret.png", "with space.png", "big16.png"]
_OPTIONS = ["", "", "", "-s 2 2 1 ", "-o 0.5 0 0 ", "-bm 2 ", "-bm nan ", "-bm 99 ", "-clamp on ", "-mm 0 1 ",
            "-blendu off -blendv off ", "-wobble 1 ", "-o ", "-type sphere "]


def make_shared(folder: Path, outside: Path) -> None:
    """The images and odd files cases name, made once: ``folder`` is where every case's
    model is written (so the names above are relative to it), ``outside`` beside it."""
    from PIL import Image

    from benchmarks.level_fuzz import _png

    folder.mkdir(parents=True, exist_ok=True)
    outside.mkdir(parents=True, exist_ok=True)
    (folder / "textures").mkdir(exist_ok=True)
    Image.new("RGB", (8, 8), (200, 120, 40)).save(folder / "good.png")
    Image.new("RGB", (8, 8), (200, 120, 40)).save(folder / "with space.png")
    Image.fromarray(np.tile(np.arange(0, 256, 32, dtype=np.uint8), (8, 1))).convert("RGB").save(folder / "grey.png")
    _png(folder / "n16.png", np.tile(np.array([32768, 32768, 65535], np.uint16), (4, 4, 1)), 2, 16)
    _png(folder / "big16.png", np.zeros((4, 4, 3), np.uint16), 2, 16, (16384, 16384))
    (folder / "garbage.png").write_bytes(bytes(range(256)) * 3)
    Image.new("RGB", (4, 4), (255, 0, 0)).save(outside / "secret.png")
    for name in ("fifo.png", "fifo.mtl"):  # textures/fifo.png is not there: its bare name is a FIFO
        if not os.path.lexists(folder / name):
            os.mkfifo(folder / name)
    (folder / "folder.png").mkdir(exist_ok=True)
    if not os.path.lexists(folder / "loop.png"):
        (folder / "loop.png").symlink_to(folder / "loop.png")


# --- cases ---------------------------------------------------------------------------------------

def _face_lines(rng: random.Random, count: int, uvs: int, normals: int, mutations: list[str]) -> list[str]:
    faces = []
    for _ in range(rng.randint(1, 4)):
        corners = []
        form = rng.choice(["v", "v/vt", "v//vn", "v/vt/vn", "v/vt/vn", "v/vt/vn", "v", "odd"])
        for _ in range(3):
            index = rng.randint(1, count)
            if form == "odd":
                index = rng.choice([0, count + 1, -count - 1, -1, 10 ** 20])
            parts = [str(index)]
            if "vt" in form:
                parts.append(str(rng.randint(1, max(uvs, 1) + rng.choice([0, 0, 0, 0, 0, 2]))))
            elif "vn" in form:
                parts.append("")
            if "vn" in form:
                parts.append(str(rng.randint(1, max(normals, 1) + rng.choice([0, 0, 0, 0, 0, 2]))))
            corners.append("/".join(parts))
        faces.append("f " + " ".join(corners))
        mutations.append(f"face {form}")
    if rng.random() < 0.2:
        faces[0] = faces[0].replace(" ", " \\\n", 1)
        mutations.append("a continued face line")
    if rng.random() < 0.1:
        faces.append("f 1 2 x")
        mutations.append("a face of text")
    return faces


def random_obj(rng: random.Random) -> ModelCase:
    mutations: list[str] = []
    count = rng.randint(3, 8)
    vertices = [f"v {rng.uniform(-1, 1):.3f} {rng.uniform(-1, 1):.3f} {rng.uniform(-1, 1):.3f}" for _ in range(count)]
    uvs = rng.choice([0, 0, count])
    normals = rng.choice([0, 1, count])
    lines = vertices + [f"vt {rng.random():.3f} {rng.random():.3f}" for _ in range(uvs)]
    late_normals = [f"vn 0 {rng.choice([-1, 1])} 0" for _ in range(normals)]
    faces = _face_lines(rng, count, uvs, normals, mutations)
    if rng.random() < 0.3:  # the normals after the faces: indices refer forward
        body = lines + ["usemtl m"] + faces + late_normals
        mutations.append("normals after the faces")
    else:
        body = lines + late_normals + ["usemtl m"] + faces
    library = rng.choice(["m.mtl", "m.mtl", "m.mtl", "# mtllib fifo.mtl", "fifo.mtl", "gone.mtl",
                          "../outside/m.mtl"])
    mutations.append(f"mtllib {library}")
    header = [library if library.startswith("#") else f"mtllib {library}"]
    mtl = ["newmtl m", f"Kd {rng.choice(['0.8 0.8 0.8', '1 0.2 0.2', 'nan 0 0', '2 2 2'])}"]
    for key in rng.sample(["Ke 0.8 0.4 0.2", "Ke 1 1 1", "Pm 1", "Pr 0.1", "refl 1", "Ke -1 0 0", "d 0.5"],
                          rng.randint(0, 3)):
        mtl.append(key)
    for _ in range(rng.randint(0, 3)):
        key = rng.choice(["map_Kd", "norm", "map_Bump", "bump", "map_Ke"])
        statement = f"{key} {rng.choice(_OPTIONS)}{rng.choice(_IMAGES)}"
        mtl.append(statement)
        mutations.append(statement)
    text = "\n".join(header + body) + "\n"
    return ModelCase("obj", {"model.obj": text.encode(), "m.mtl": ("\n".join(mtl) + "\n").encode()}, mutations)


def _png_bytes(colour: tuple[int, int, int]) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.new("RGB", (4, 4), colour).save(out, format="PNG")
    return out.getvalue()


def random_glb(rng: random.Random) -> ModelCase:
    """A sphere-ish mesh (an octahedron) drawn by 1 to 40 nodes, its one material's slots
    naming images from the pools."""
    mutations: list[str] = []
    positions = np.array([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)], np.float32) * 0.3
    indices = np.array([(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)],
                       np.uint32)
    uvs = (positions[:, :2] + 0.5).astype(np.float32)
    blob = bytearray()
    views = []

    def view(data: bytes) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob.extend(data)
        return len(views) - 1

    accessors = [
        {"bufferView": view(positions.tobytes()), "componentType": 5126, "count": 6, "type": "VEC3",
         "min": positions.min(0).tolist(), "max": positions.max(0).tolist()},
        {"bufferView": view(uvs.tobytes()), "componentType": 5126, "count": 6, "type": "VEC2"},
        {"bufferView": view(indices.tobytes()), "componentType": 5125, "count": 24, "type": "SCALAR"},
    ]
    images = []
    for _ in range(rng.randint(0, 3)):
        choice = rng.choice(["file", "file", "embedded", "base64", "data", "bad view"])
        if choice == "file":
            images.append({"uri": rng.choice(_IMAGES).replace(" ", "%20")})
        elif choice == "embedded":
            images.append({"bufferView": view(_png_bytes((30, 200, 90))), "mimeType": "image/png"})
        elif choice == "base64":
            images.append({"uri": "data:image/png;base64," + base64.b64encode(_png_bytes((90, 30, 200))).decode()})
        elif choice == "data":
            images.append({"uri": "data:,fifo.png"})
        else:
            images.append({"bufferView": 99})
        mutations.append(f"image {choice} {images[-1].get('uri', '')[:30]}")
    material: dict = {"name": "fuzzed", "pbrMetallicRoughness": {
        "baseColorFactor": [rng.random(), rng.random(), rng.random(), 1.0],
        "metallicFactor": rng.choice([0.0, 1.0, 1.0, 2.0]), "roughnessFactor": rng.choice([0.0, 0.3, 1.0])}}
    for slot in rng.sample(["baseColorTexture", "metallicRoughnessTexture", "normalTexture", "emissiveTexture",
                            "occlusionTexture"], rng.randint(0, 3)):
        texture = {"index": rng.choice([0, 0, 0, 1, 2, 7])}
        if slot == "occlusionTexture" and rng.random() < 0.5:
            texture["strength"] = rng.choice([0.0, 0.5, 1.0, 2.0, -1.0, "full"])
        if rng.random() < 0.2:  # a UV set (maybe one the mesh lacks, or no number) or a transform of its own
            texture.update(rng.choice([{"texCoord": 1}, {"texCoord": 2}, {"texCoord": -1}, {"texCoord": "1"},
                                       {"extensions": {"KHR_texture_transform": {}}},
                                       {"extensions": {"KHR_texture_transform": {"scale": [2, 2], "texCoord": 1}}},
                                       {"extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0]}}}]))
        (material["pbrMetallicRoughness"] if slot in ("baseColorTexture", "metallicRoughnessTexture")
         else material)[slot] = texture
        mutations.append(f"{slot} -> {texture}")
    if rng.random() < 0.4:  # glTF's alpha modes and double-sided faces
        material["alphaMode"] = rng.choice(["MASK", "MASK", "BLEND", "OPAQUE", "CLIP"])
        if rng.random() < 0.5:
            material["alphaCutoff"] = rng.choice([0.0, 0.5, 0.9, 1.0, 1.5, -0.2])
        material["doubleSided"] = rng.random() < 0.5
        mutations.append(f"alphaMode {material['alphaMode']} cutoff {material.get('alphaCutoff')} "
                         f"doubleSided {material['doubleSided']}")
    if rng.random() < 0.5:
        material["emissiveFactor"] = rng.choice([[1, 1, 1], [0.8, 0.4, 0.2], [0, 0, 0], [-1, 0, 0]])
    nodes = rng.choice([1, 1, 2, 12, 40])
    mutations.append(f"{nodes} nodes, metallic {material['pbrMetallicRoughness']['metallicFactor']}")
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(nodes))}],
           "nodes": [{"mesh": 0, "translation": [0.7 * (i % 8) - 2.5, 0.7 * (i // 8), 0.0]} for i in range(nodes)],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                       "material": 0}]}],
           "materials": [material], "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob)}]}
    if images:
        doc["images"] = images
        doc["textures"] = [{"source": rng.choice([i, i, i, 9])} for i in range(len(images))]
    if rng.random() < 0.3:  # a second UV set: float, normalised bytes, too few or of the wrong type
        kind = rng.choice(["float", "float", "bytes", "short", "scalar"])
        second = (uvs[:, ::-1] * (255 if kind == "bytes" else 1)).astype(np.uint8 if kind == "bytes" else np.float32)
        accessors.append({"bufferView": view(second.tobytes()), "componentType": 5121 if kind == "bytes" else 5126,
                          "count": 5 if kind == "short" else 6, "type": "SCALAR" if kind == "scalar" else "VEC2",
                          **({"normalized": True} if kind == "bytes" else {})})
        doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = len(accessors) - 1
        mutations.append(f"TEXCOORD_1 {kind}")
    if rng.random() < 0.15:
        _meshopt(rng, doc, view, positions, mutations)
    elif rng.random() < 0.15:
        _draco(rng, doc, view, positions, indices, mutations)
    if rng.random() < 0.25:
        _skin(rng, doc, view, mutations)
    if rng.random() < 0.25:
        _morphs(rng, doc, view, mutations)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    while len(blob) % 4:
        blob.append(0)
    body = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(blob), b"BIN\0") + bytes(blob)
    return ModelCase("glb", {"model.glb": struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body}, mutations)


def _meshopt(rng: random.Random, doc: dict, view, positions: np.ndarray, mutations: list[str]) -> None:
    """Pack the positions' view with meshoptimizer (EXT_meshopt_compression, required), its
    extension maybe spoilt: a wrong stride, count, mode or filter, bytes cut short or
    scrambled; without the meshopt package the file is refused naming it."""
    try:
        import meshopt
    except ImportError:
        return
    packed = bytearray(meshopt.encode_gltf_buffer(positions.view(np.uint8).reshape(-1, 12), "ATTRIBUTES"))
    ext = {"buffer": 0, "byteOffset": 0, "byteLength": len(packed), "byteStride": 12, "count": 6,
           "mode": "ATTRIBUTES"}
    spoil = rng.choice(["none", "none", "stride", "count", "mode", "filter", "short", "scramble"])
    if spoil == "stride":
        ext["byteStride"] = rng.choice([0, 6, 16, 300])
    elif spoil == "count":
        ext["count"] = rng.choice([0, 5, 7, -1, 10 ** 9])
    elif spoil == "mode":
        ext["mode"] = rng.choice(["TRIANGLES", "POINTS", 3])
    elif spoil == "filter":
        ext["filter"] = rng.choice(["OCTAHEDRAL", "QUATERNION", "BLUR"])
    elif spoil == "short":
        ext["byteLength"] = len(packed) // 2
    elif spoil == "scramble":
        packed[len(packed) // 2:] = bytes(rng.randrange(256) for _ in range(len(packed) - len(packed) // 2))
    ext["byteOffset"] = doc["bufferViews"][view(bytes(packed))]["byteOffset"]  # (in the file's own buffer)
    mutations.append(f"meshopt positions, {spoil}")
    doc["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": ext}
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_meshopt_compression"]


def _draco(rng: random.Random, doc: dict, view, positions: np.ndarray, indices: np.ndarray,
           mutations: list[str]) -> None:
    """Code the primitive's positions and triangles with Draco (KHR_draco_mesh_compression,
    required), maybe spoilt: bytes scrambled or cut short, an attribute id the data lacks, a
    view the file lacks; without the DracoPy package the file is refused naming it."""
    try:
        import DracoPy
    except ImportError:
        return
    coded = bytearray(DracoPy.encode(positions, indices, preserve_order=True))
    unique = DracoPy.decode(bytes(coded)).attributes[0]["unique_id"]
    spoil = rng.choice(["none", "none", "scramble", "short", "id", "view"])
    if spoil == "scramble":
        coded[len(coded) // 2:] = bytes(rng.randrange(256) for _ in range(len(coded) - len(coded) // 2))
    elif spoil == "short":
        coded = coded[: len(coded) // 2]
    ext = {"bufferView": 99 if spoil == "view" else view(bytes(coded)),
           "attributes": {"POSITION": unique + 5 if spoil == "id" else unique}}
    primitive = doc["meshes"][0]["primitives"][0]
    primitive["extensions"] = {"KHR_draco_mesh_compression": ext}
    primitive["attributes"] = {"POSITION": 0}
    mutations.append(f"draco positions, {spoil}")
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]


def _skin(rng: random.Random, doc: dict, view, mutations: list[str]) -> None:
    """Skin the mesh by two joint nodes: JOINTS_0 that may name a joint the skin lacks,
    WEIGHTS_0 as floats or normalised bytes that may be negative or all zero, inverse bind
    matrices that may be too few or not affine, a node naming a skin the file lacks."""
    accessors = doc["accessors"]
    joints = np.array([[rng.choice([0, 1]) for _ in range(4)] for _ in range(6)], np.uint8)
    weights = np.array([[rng.choice([0.0, 0.25, 0.5, 1.0]) for _ in range(4)] for _ in range(6)], np.float32)
    weights[:, 0] += 0.1  # (every vertex follows some joint, unless made otherwise below)
    if rng.random() < 0.15:
        joints[rng.randrange(6), 0] = 7   # a joint the skin lacks
    if rng.random() < 0.15:
        weights[rng.randrange(6)] = rng.choice([0.0, -0.5])   # a vertex following nothing, or negative
    if rng.random() < 0.3:
        weights = (np.clip(weights, 0.0, 1.0) * 255).astype(np.uint8)
    accessors.append({"bufferView": view(joints.tobytes()), "componentType": 5121, "count": 6, "type": "VEC4"})
    accessors.append({"bufferView": view(weights.tobytes()), "componentType": 5126 if weights.dtype == np.float32
                      else 5121, "count": 6, "type": "VEC4", **({} if weights.dtype == np.float32
                                                               else {"normalized": True})})
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    attributes["JOINTS_0"], attributes["WEIGHTS_0"] = len(accessors) - 2, len(accessors) - 1
    binds = np.tile(np.eye(4, dtype=np.float32), (rng.choice([2] * 6 + [1]), 1, 1))
    if rng.random() < 0.08:
        binds[0, 3, 0] = 1.0  # not affine
    accessors.append({"bufferView": view(binds.transpose(0, 2, 1).tobytes()), "componentType": 5126,
                      "count": len(binds), "type": "MAT4"})
    first = len(doc["nodes"])
    doc["nodes"] += [{"name": "hip", "children": [first + 1]}, {"name": "knee", "translation": [0.0, 0.3, 0.0]}]
    doc["scenes"][0]["nodes"].append(first)
    doc["skins"] = [{"joints": rng.choice([[first, first + 1]] * 6 + [[first, 99], []]),
                     "inverseBindMatrices": len(accessors) - 1}]
    doc["nodes"][0]["skin"] = rng.choice([0] * 9 + [3])
    mutations.append(f"skin {doc['skins'][0]['joints']} node skin {doc['nodes'][0]['skin']}, {len(binds)} binds, "
                     f"weights {weights.dtype}")


def _morphs(rng: random.Random, doc: dict, view, mutations: list[str]) -> None:
    """One or two morph targets, dense or sparse (indices that may run past the vertices or
    not increase), the mesh's weights that may be too few, and a clip playing them."""
    accessors = doc["accessors"]
    targets = []
    for _ in range(rng.choice([1, 2])):
        offsets = np.array([[rng.uniform(-0.2, 0.2) for _ in range(3)] for _ in range(6)], np.float32)
        if rng.random() < 0.5:
            accessors.append({"bufferView": view(offsets.tobytes()), "componentType": 5126, "count": 6, "type": "VEC3"})
        else:
            moved = np.array(rng.choice([[1, 3]] * 3 + [[0], [3, 1], [2, 9]]), np.uint16)
            accessors.append({"componentType": 5126, "count": 6, "type": "VEC3", "sparse": {
                "count": len(moved), "indices": {"bufferView": view(moved.tobytes()), "componentType": 5123},
                "values": {"bufferView": view(offsets[: len(moved)].tobytes())}}})
        targets.append({"POSITION": len(accessors) - 1})
    doc["meshes"][0]["primitives"][0]["targets"] = targets
    doc["meshes"][0]["weights"] = rng.choice([[0.5] * len(targets)] * 6 + [[1.0] * 3, ["x"]])
    times = np.array([0.0, 1.0], np.float32)
    values = np.array([rng.uniform(-1, 2) for _ in range(2 * len(targets) + rng.choice([0] * 6 + [1]))], np.float32)
    accessors.append({"bufferView": view(times.tobytes()), "componentType": 5126, "count": 2, "type": "SCALAR",
                      "min": [0.0], "max": [1.0]})
    accessors.append({"bufferView": view(values.tobytes()), "componentType": 5126, "count": len(values),
                      "type": "SCALAR"})
    doc["animations"] = [{"name": "Wobble", "samplers": [{"input": len(accessors) - 2, "output": len(accessors) - 1}],
                          "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    mutations.append(f"{len(targets)} morph targets, weights {doc['meshes'][0]['weights']}, {len(values)} keyed")


def _glb_with(data: bytes, old: bytes, new: bytes) -> bytes:
    """A GLB (as ``random_glb`` writes it) with ``old`` replaced in its JSON chunk."""
    length = struct.unpack("<I", data[12:16])[0]
    text = data[20:20 + length].replace(old, new).rstrip(b" ")
    text += b" " * (-len(text) % 4)
    rest = data[20 + length:]
    body = struct.pack("<I4s", len(text), b"JSON") + text + rest
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def random_model_case(rng: random.Random) -> ModelCase:
    return random_obj(rng) if rng.random() < 0.6 else random_glb(rng)


# --- running -------------------------------------------------------------------------------------

class ModelFuzzer:
    """One engine on a small lit scene; each case's model is written in ``folder / "models"``
    (beside the shared files), loaded, spawned, rendered FRAMES frames and deleted."""

    def __init__(self, ctx, folder: Path) -> None:
        from pyglm import glm

        from components import Camera, DirectionalLight, Material, MeshRef, Skybox, Transform, look_rotation
        from engine.assets.mesh import box
        from engine.core.game import Game
        from engine.render.targets import CaptureTarget
        from shell.app import Engine

        class Scene(Game):
            title = "model fuzz"

            def build(self, world) -> None:
                eye = glm.vec3(0, 1.0, 4)
                world.spawn(Transform(position=eye, rotation=look_rotation(-eye)), Camera())
                world.spawn(Skybox(face_size=8))
                world.spawn(DirectionalLight(direction=(-0.3, -1, -0.5), intensity=2.0))
                world.spawn(Transform(position=(0, -1.0, 0)), MeshRef(box((4, 0.1, 4))), Material())

        self.ctx = ctx
        self.folder = folder / "models"
        self.outside = folder / "outside"
        make_shared(self.folder, self.outside)
        self.engine = Engine(Scene(), ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.baseline = set(self.world.entities())
        self.refused = self.rendered = 0

    def close(self) -> None:
        self.capture.release()
        self.engine.close()

    def run(self, case: ModelCase, index: int = 0) -> str | None:
        """None when the case passed, else why it failed."""
        from benchmarks.level_fuzz import CASE_SECONDS, _deadline, _Hung, render_checked
        from engine.assets.models import spawn_model
        from engine.core.errors import AssetError

        names = {}
        for name, data in case.files.items():
            target = self.folder / f"case_{index}_{name}"
            names[name] = target
            text = data.replace(b"@OUTSIDE@", str(self.outside.resolve()).encode())
            if name.endswith(".glb") and text != data:  # the JSON chunk grew: its lengths written again
                text = _glb_with(data, b"@OUTSIDE@", str(self.outside.resolve()).encode())
            if name.endswith(".obj"):
                text = text.replace(b"mtllib m.mtl", f"mtllib case_{index}_m.mtl".encode())
            target.write_bytes(text)
        path = names[f"model.{case.kind}"]
        try:
            with warnings.catch_warnings(), _deadline(CASE_SECONDS):
                warnings.simplefilter("ignore")
                spawn_model(self.world, path, position=(0.0, 0.0, 0.0))
        except AssetError as exc:
            if str(path) not in str(exc):
                return f"AssetError without the model's file name: {exc}"
            if set(self.world.entities()) != self.baseline:
                return "refused, but left entities in the world"
            self.refused += 1
            return None
        except _Hung:
            return f"loading hung for more than {CASE_SECONDS:g} s (a FIFO opened?)"
        except Exception as exc:  # noqa: BLE001 - any other kind is what the fuzz is looking for
            return f"spawn_model raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        finally:
            for target in names.values():
                target.unlink(missing_ok=True)
        try:
            problem = render_checked(self.ctx, self.engine, self.capture.framebuffer)
        finally:
            for entity in list(self.world.entities()):
                if entity not in self.baseline:
                    self.world.delete_entity(entity)
        if problem is None:
            self.rendered += 1
        return problem


def fuzz_models(ctx, folder: Path, cases: int, seed: int = 0, report=None) -> tuple[int, list, dict[str, int]]:
    """Run ``cases`` model cases (``benchmarks.fuzz_cases.run_cases``), their files in ``folder``."""
    from benchmarks.fuzz_cases import run_cases

    return run_cases(ModelFuzzer(ctx, folder), random_model_case, cases, seed, report)
