"""A scene's meshes and their materials written as glTF 2.0: a binary ``.glb``, or a ``.gltf``
with its buffer embedded (one file either way), for ``--export-scene``.

Each part is one node (named as the caller says: ``shell/capture.py`` names them by entity)
holding one mesh in world space (its transform already applied, the node's own the
identity; a skinned or morphed mesh at rest, as the file is a still scene), with its
normals, UV sets, vertex colours and a metallic-roughness material
written as this engine's own glTF loader (``engine/assets/mesh.py``) reads them back:

* ``Material``: the base colour and its texture, metallic, roughness and their map, the
  normal map and its scale, the occlusion map and its strength, ``alpha_cutoff`` (MASK), a
  colour whose alpha is under 1 (BLEND), ``double_sided``, and the extensions the loader
  reads: ``unlit``, ``clearcoat``, ``sheen``, ``iridescence``, ``anisotropy``,
  ``diffuse_transmission`` and the dielectric's reflectance and ``specular_color``
  (``KHR_materials_specular`` over an index of 1.5).  A map read from the second UV set
  (``Material.second_uv_maps``) says ``texCoord`` 1.  The lightmap has no glTF slot: left out.
* ``Emissive``: the emitted colour (power x the diffuse colour, or power x the emissive map),
  past 1 through ``KHR_materials_emissive_strength``.
* ``Refractive``: glass (``KHR_materials_transmission``, ``_ior``, ``_volume`` for a solid,
  ``_dispersion``), the colour's alpha its transmission; a ``Water``'s surface: smooth glass
  of the water's index; a ``Mirror``: a smooth metal of its tint, as metallic as it
  reflects (the loader makes a flat metal a mirror again).

Lights are ``KHR_lights_punctual``'s (``ExportLight``): a sun, a lamp, a spot up to 90 degrees
(glTF's widest cone).  What the extension has no word for goes in the light's ``extras``
under ``"speculum"``, each field the engine's light gives other than its default, by its
name there (``model_lights.LAMP_FIELDS``, ``SUN_FIELDS``): a lamp's shape (a sphere's
``radius``, a ``rectangle``, a tube's ``length``), its shadows and how many mirrors its light
bounces off, a spot wider than 90 degrees, a sun's cascades, disc and body; the loader reads
them back (``engine/assets/model_lights.py``; other readers see the light the extension
describes).  A lamp's cookie (an image) is left out.
Cameras are core glTF's (``ExportCamera``).

Images are PNGs in the buffer (16-bit maps rounded to 8 bits).  glTF puts the UVs' origin at
the image's top left, the engine at its bottom left: v is written as 1 - v."""
from __future__ import annotations

import base64
import dataclasses
import io
import json
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from components import Material
from engine.assets.model_lights import LIGHT_EXTRAS
from engine.assets.texture_data import TextureData

# glTF constants
_FLOAT, _UINT = 5126, 5125
_ARRAY, _ELEMENTS = 34962, 34963
_REPEAT, _LINEAR, _LINEAR_MIPMAP_LINEAR = 10497, 9729, 9987
_DIELECTRIC_F0 = 0.04   # Schlick's f0 at glTF's default index, 1.5

# Material fields that are maps, and their glTF slot (the lightmap has none).
MAP_SLOTS = {"texture": "baseColorTexture", "metallic_roughness_map": "metallicRoughnessTexture",
             "normal_map": "normalTexture", "occlusion_map": "occlusionTexture", "emissive_map": "emissiveTexture"}


@dataclass
class ExportPart:
    """One node's mesh in world space and what it is drawn with: ``material`` (None: the
    engine's default), ``emission`` (``Emissive.power``; 0: none), ``glass`` (a
    ``Refractive``'s ior, solid and dispersion; None: not glass), ``water_ior`` (a ``Water``'s
    index; None: not water) and ``mirror`` (a ``Mirror``'s tint, rate and roughness; None:
    not a mirror)."""

    name: str
    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    indices: np.ndarray
    material: object | None = None
    second_uvs: np.ndarray | None = None
    colors: np.ndarray | None = None
    emission: float = 0.0
    glass: tuple[float, bool, float] | None = None
    water_ior: float | None = None
    mirror: tuple[tuple[float, float, float], float, float] | None = None


@dataclass
class ExportLight:
    """A light as ``KHR_lights_punctual`` has it: ``kind`` "directional", "point" or "spot",
    linear ``color`` in [0, 1], ``intensity`` (the engine's units are the extension's: lux,
    candela), ``range`` (None: none), a spot's cone angles from its axis (radians) and
    ``matrix`` its node's world transform (column-major; the light shines along its -Z)."""

    name: str
    kind: str
    color: tuple[float, float, float]
    intensity: float
    matrix: list[float]
    range: float | None = None
    inner_cone: float = 0.0
    outer_cone: float = math.pi / 4.0
    # The engine's fields the extension has no word for (extras: model_lights.LAMP_FIELDS, SUN_FIELDS)
    fields: dict[str, object] = dataclasses.field(default_factory=dict)


@dataclass
class ExportCamera:
    """A camera: ``fov_y`` in degrees, or ``ortho_height`` (not None: orthographic), its
    planes, and ``matrix`` its node's world transform (column-major; it looks along -Z).
    ``aspect``: the picture's width / height, which an orthographic camera's ``xmag`` spans
    (glTF's projection is x / xmag, y / ymag: equal ones would make a viewer draw it square)."""

    name: str
    fov_y: float
    near: float
    far: float
    matrix: list[float]
    ortho_height: float | None = None
    aspect: float = 1.0


class _Buffer:
    """The one buffer: its views (4-byte aligned), accessors and images as glTF JSON lists."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, raw: bytes, target: int | None = None) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        entry = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            entry["target"] = target
        self.data += raw
        self.views.append(entry)
        return len(self.views) - 1

    def accessor(self, values: np.ndarray, kind: str, bounds: bool = False, target: int = _ARRAY) -> int:
        values = np.ascontiguousarray(values, np.uint32 if kind == "SCALAR" else np.float32)
        entry = {"bufferView": self.view(values.tobytes(), target), "componentType":
                 _UINT if kind == "SCALAR" else _FLOAT, "count": len(values), "type": kind}
        if bounds:
            entry["min"] = [float(v) for v in values.min(axis=0)]
            entry["max"] = [float(v) for v in values.max(axis=0)]
        self.accessors.append(entry)
        return len(self.accessors) - 1


class _Images:
    """Each TextureData once, as a PNG in the buffer and a texture sampling it."""

    def __init__(self, buffer: _Buffer) -> None:
        self.buffer = buffer
        self.images: list[dict] = []
        self.textures: list[dict] = []
        self._index: dict[int, int] = {}

    def texture(self, data: TextureData) -> int:
        found = self._index.get(id(data))
        if found is None:
            from PIL import Image

            png = io.BytesIO()
            Image.fromarray(data.as_8_bits(), "RGBA").save(png, format="PNG")
            view = self.buffer.view(png.getvalue())
            self.images.append({"bufferView": view, "mimeType": "image/png", "name": data.name})
            self.textures.append({"sampler": 0, "source": len(self.images) - 1})
            found = self._index[id(data)] = len(self.textures) - 1
        return found


def _numbers(values, count: int) -> list[float]:
    return [float(v) for v in list(values)[:count]]


def material_json(part: ExportPart, images: _Images, used: set[str]) -> dict:
    """The glTF material of ``part`` (``used`` gathers the extensions it names)."""
    material = part.material if part.material is not None else Material()
    color = _numbers(material.color, 4)
    second = set(material.second_uv_maps)
    metallic, roughness = float(material.metallic), float(material.roughness)
    if part.mirror is not None:  # a mirror: a smooth metal, as metallic as it reflects
        tint, rate, mirror_roughness = part.mirror
        color[:3] = [c * t for c, t in zip(color[:3], tint, strict=True)]
        metallic, roughness = rate, mirror_roughness
    if part.water_ior is not None:
        metallic, roughness = 0.0, 0.0
    pbr = {"baseColorFactor": color, "metallicFactor": metallic, "roughnessFactor": roughness}
    out: dict = {"pbrMetallicRoughness": pbr, "doubleSided": bool(material.double_sided)}
    extensions: dict = {}

    def slot(field: str, data: TextureData | None, extra: dict | None = None) -> dict | None:
        if data is None:
            return None
        info = {"index": images.texture(data), **(extra or {})}
        if field in second:
            info["texCoord"] = 1
        return info

    for field in ("texture", "metallic_roughness_map"):
        info = slot(field, getattr(material, field))
        if info is not None:
            pbr[MAP_SLOTS[field]] = info
    normal = slot("normal_map", material.normal_map, {"scale": float(material.normal_scale)})
    if normal is not None:
        out["normalTexture"] = normal
    occlusion = slot("occlusion_map", material.occlusion_map, {"strength": float(material.occlusion_strength)})
    if occlusion is not None:
        out["occlusionTexture"] = occlusion
    if part.emission > 0.0:
        # The engine emits power x the emissive map, or, without one, power x its diffuse
        # colour (the colour times its texture): glTF's emissiveFactor x emissiveTexture.
        if material.emissive_map is not None:
            emitted, image, field = [part.emission] * 3, material.emissive_map, "emissive_map"
        else:
            emitted, image, field = [c * part.emission for c in color[:3]], material.texture, "texture"
        strength = max(emitted)
        info = slot(field, image)
        if info is not None:
            out["emissiveTexture"] = info
        if strength > 1.0:
            emitted = [e / strength for e in emitted]
            extensions["KHR_materials_emissive_strength"] = {"emissiveStrength": strength}
        out["emissiveFactor"] = emitted
    if material.alpha_cutoff is not None:
        out["alphaMode"], out["alphaCutoff"] = "MASK", float(material.alpha_cutoff)
    elif color[3] < 1.0 and part.glass is None and part.water_ior is None:
        out["alphaMode"] = "BLEND"
    glass_ior = None
    if part.glass is not None or part.water_ior is not None:
        glass_ior, solid, dispersion = part.glass if part.glass is not None else (part.water_ior, False, 0.0)
        extensions["KHR_materials_transmission"] = {"transmissionFactor": 1.0 - color[3]}
        pbr["baseColorFactor"] = [*color[:3], 1.0]
        extensions["KHR_materials_ior"] = {"ior": float(glass_ior)}
        if solid:
            extensions["KHR_materials_volume"] = {"thicknessFactor": 1.0}
        if dispersion > 0.0:
            extensions["KHR_materials_dispersion"] = {"dispersion": float(dispersion)}
    if material.unlit:
        extensions["KHR_materials_unlit"] = {}
    if material.clearcoat > 0.0:
        extensions["KHR_materials_clearcoat"] = {"clearcoatFactor": float(material.clearcoat),
                                                 "clearcoatRoughnessFactor": float(material.clearcoat_roughness)}
    if max(_numbers(material.sheen_color, 3)) > 0.0:
        extensions["KHR_materials_sheen"] = {"sheenColorFactor": _numbers(material.sheen_color, 3),
                                             "sheenRoughnessFactor": float(material.sheen_roughness)}
    if material.iridescence > 0.0:
        extensions["KHR_materials_iridescence"] = {
            "iridescenceFactor": float(material.iridescence), "iridescenceIor": float(material.iridescence_ior),
            "iridescenceThicknessMaximum": float(material.iridescence_thickness)}
    if material.anisotropy > 0.0:
        extensions["KHR_materials_anisotropy"] = {"anisotropyStrength": float(material.anisotropy),
                                                  "anisotropyRotation": math.radians(material.anisotropy_direction)}
    if material.diffuse_transmission > 0.0:
        extensions["KHR_materials_diffuse_transmission"] = {
            "diffuseTransmissionFactor": float(material.diffuse_transmission),
            "diffuseTransmissionColorFactor": _numbers(material.diffuse_transmission_color, 3)}
    specular = [0.16 * float(material.reflectance) ** 2 * c for c in _numbers(material.specular_color, 3)]
    if glass_ior is None and specular != [_DIELECTRIC_F0] * 3:
        # The engine's f0 (0.16 reflectance^2 x specular_color) over glTF's at an index of 1.5
        extensions["KHR_materials_specular"] = {"specularColorFactor": [f / _DIELECTRIC_F0 for f in specular]}
    if extensions:
        out["extensions"] = extensions
        used.update(extensions)
    return out


def _light_json(light: ExportLight) -> dict:
    entry = {"name": light.name, "type": light.kind, "color": list(light.color), "intensity": light.intensity}
    if light.range is not None:
        entry["range"] = light.range
    if light.kind == "spot":
        entry["spot"] = {"innerConeAngle": light.inner_cone, "outerConeAngle": light.outer_cone}
    if light.fields:
        entry["extras"] = {LIGHT_EXTRAS: dict(light.fields)}
    return entry


def _camera_json(camera: ExportCamera) -> dict:
    if camera.ortho_height is not None:
        half = camera.ortho_height / 2.0
        return {"name": camera.name, "type": "orthographic",
                "orthographic": {"xmag": half * camera.aspect, "ymag": half, "znear": camera.near, "zfar": camera.far}}
    return {"name": camera.name, "type": "perspective",
            "perspective": {"yfov": math.radians(camera.fov_y), "znear": camera.near, "zfar": camera.far}}


def gltf_document(parts: Sequence[ExportPart], lights: Sequence[ExportLight] = (),
                  cameras: Sequence[ExportCamera] = ()) -> tuple[dict, bytes]:
    """The glTF JSON of ``parts``, ``lights`` and ``cameras`` and its one buffer's bytes (not
    yet named in it)."""
    buffer = _Buffer()
    images = _Images(buffer)
    used: set[str] = set()
    meshes, nodes, materials = [], [], []
    for part in parts:
        attributes = {"POSITION": buffer.accessor(part.positions, "VEC3", bounds=True),
                      "NORMAL": buffer.accessor(part.normals, "VEC3")}
        for number, uvs in enumerate((part.uvs, part.second_uvs)):
            if uvs is not None:
                flipped = np.array(uvs, np.float32)
                flipped[:, 1] = 1.0 - flipped[:, 1]
                attributes[f"TEXCOORD_{number}"] = buffer.accessor(flipped, "VEC2")
        if part.colors is not None:
            attributes["COLOR_0"] = buffer.accessor(part.colors, "VEC4" if part.colors.shape[1] == 4 else "VEC3")
        materials.append(material_json(part, images, used))
        indices = buffer.accessor(np.asarray(part.indices).reshape(-1), "SCALAR", target=_ELEMENTS)
        meshes.append({"name": part.name, "primitives": [{"attributes": attributes, "indices": indices,
                                                          "material": len(materials) - 1}]})
        nodes.append({"name": part.name, "mesh": len(meshes) - 1})
    for number, light in enumerate(lights):
        nodes.append({"name": light.name, "matrix": list(light.matrix),
                      "extensions": {"KHR_lights_punctual": {"light": number}}})
    for number, camera in enumerate(cameras):
        nodes.append({"name": camera.name, "matrix": list(camera.matrix), "camera": number})
    doc: dict = {"asset": {"version": "2.0", "generator": "Speculum --export-scene"},
                 "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": meshes,
                 "materials": materials, "accessors": buffer.accessors, "bufferViews": buffer.views,
                 "buffers": [{"byteLength": len(buffer.data)}]}
    if images.images:
        doc["images"], doc["textures"] = images.images, images.textures
        doc["samplers"] = [{"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR, "wrapS": _REPEAT,
                            "wrapT": _REPEAT}]
    if lights:
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [_light_json(light) for light in lights]}}
        used.add("KHR_lights_punctual")
    if cameras:
        doc["cameras"] = [_camera_json(camera) for camera in cameras]
    if used:
        doc["extensionsUsed"] = sorted(used)
    return doc, bytes(buffer.data)


def write_gltf(path: str | Path, parts: Sequence[ExportPart], lights: Sequence[ExportLight] = (),
               cameras: Sequence[ExportCamera] = ()) -> Path:
    """Write ``parts``, ``lights`` and ``cameras`` to ``path``: binary glTF for ``.glb``, JSON
    glTF with its buffer as a data URI otherwise."""
    path = Path(path)
    doc, data = gltf_document(parts, lights, cameras)
    if path.suffix.lower() == ".glb":
        data += b"\0" * (-len(data) % 4)
        doc["buffers"][0]["byteLength"] = len(data)
        text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
        text += b" " * (-len(text) % 4)
        chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(data), b"BIN\0") + data
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    else:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
        path.write_text(json.dumps(doc, indent=1))
    return path
