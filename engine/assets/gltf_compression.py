"""Compressed glTF: ``KHR_draco_mesh_compression``'s primitives, ``EXT_meshopt_compression``'s
buffer views and ``KHR_texture_basisu``'s KTX2 images made plain before trimesh reads the file.

Blender and Sketchfab write Draco (a primitive's geometry as one Draco-coded bufferView, a
tenth of the bytes); gltfpack and glTF-Transform write meshopt (vertex and index data packed
by meshoptimizer's codecs, often with ``KHR_mesh_quantization``) and Basis Universal KTX2
textures.  Each Draco primitive is decoded (``decode_draco_primitives``: the DracoPy package,
Google's decoder) and its accessors pointed at the decoded attributes and triangles; each
meshopt view is decoded (``decode_meshopt_views``: the meshopt package, its filters undone:
octahedral normals, quaternions, exponents, colours); each KTX2 image a texture names is
transcoded to PNG (``decode_basisu_textures``: the alktx2 package, Basis Universal's
transcoder) and the texture pointed at it.  Decoded data goes into a buffer of the engine's
making (a ``data:`` URI).  The packages are optional (``pip install speculum[compressed]``):
a file that requires an extension whose package is missing is refused naming the package
(``missing_decoders``); one that only uses it keeps its fallback (plain data or a PNG).
"""
from __future__ import annotations

import base64
import importlib
from collections.abc import Callable

import numpy as np

from engine.assets.gltf_accessors import BufferBytes
from engine.assets.texture_data import ASSET_MEMORY_BUDGET
from engine.core.errors import AssetError

MESHOPT = "EXT_meshopt_compression"
BASISU = "KHR_texture_basisu"
DRACO = "KHR_draco_mesh_compression"
# extension -> the package that decodes it
DECODERS = {MESHOPT: "meshopt", BASISU: "alktx2", DRACO: "DracoPy"}
MESHOPT_MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
MESHOPT_FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL", "COLOR")


def _decoder(extension: str):
    """The package that decodes ``extension`` (None: not installed)."""
    try:
        return importlib.import_module(DECODERS[extension])
    except ImportError:
        return None


def missing_decoders(required: list[str]) -> list[str]:
    """Of the extensions a file requires, those this engine reads only with a package that
    is not installed, each with the package (for the refusal: "... install meshopt")."""
    return [f"{name} (needs the {DECODERS[name]} package: pip install {DECODERS[name]})"
            for name in required if name in DECODERS and _decoder(name) is None]


# glTF componentType of the arrays a Draco primitive decodes to (its floats, its integer attributes)
_DRACO_TYPES = {np.dtype(np.float32): 5126, np.dtype(np.uint8): 5121, np.dtype(np.uint16): 5123,
                np.dtype(np.uint32): 5125, np.dtype(np.int8): 5120, np.dtype(np.int16): 5122}


def decode_draco_primitives(doc: dict, buffer_bytes: BufferBytes, what: str) -> int:
    """Decode every primitive ``KHR_draco_mesh_compression`` codes and point its attribute and
    index accessors at the decoded arrays (in a new buffer appended to ``doc["buffers"]``);
    how many were decoded.  Without the DracoPy package (the file only uses the extension:
    its accessors hold the plain data too) nothing is done.  A primitive whose Draco view
    lies outside its buffer, whose data does not decode, or which names an attribute its
    Draco data lacks, is an AssetError naming it."""
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    coded = [(m, p, primitive) for m, mesh in enumerate(meshes) if isinstance(mesh, dict)
             for p, primitive in enumerate(mesh.get("primitives") or []) if isinstance(primitive, dict)
             and isinstance(primitive.get("extensions"), dict) and DRACO in primitive["extensions"]]
    draco = _decoder(DRACO) if coded else None
    if draco is None:
        return 0
    accessors = doc.get("accessors") if isinstance(doc.get("accessors"), list) else []
    views = doc.setdefault("bufferViews", [])
    buffers = doc.setdefault("buffers", [])
    decoded = bytearray()
    pointed: list[tuple[dict, np.ndarray]] = []
    for m, p, primitive in coded:
        label = f"{what}: mesh {m}'s primitive {p} ({DRACO})"
        ext = primitive["extensions"][DRACO]
        view = ext.get("bufferView") if isinstance(ext, dict) else None
        names = ext.get("attributes") if isinstance(ext, dict) else None
        if isinstance(view, bool) or not isinstance(view, int) or not 0 <= view < len(views) \
                or not isinstance(views[view], dict) or not isinstance(names, dict):
            raise AssetError(f"{label}: needs a bufferView the file has and an attributes object, got {ext!r}")
        data = _view_bytes(views[view], buffer_bytes, label)
        try:
            mesh = draco.decode(bytes(data))
        except Exception as exc:  # (the decoder's own errors: not Draco, or damaged)
            raise AssetError(f"{label}: its data does not decode ({type(exc).__name__}: {exc})") from None
        attributes = primitive.get("attributes") if isinstance(primitive.get("attributes"), dict) else {}
        for name, unique in names.items():
            accessor = attributes.get(name)
            found = mesh.get_attribute_by_unique_id(unique) if isinstance(unique, int) else None
            if found is None or not _index_in(accessor, accessors):
                raise AssetError(f"{label}: attribute {name} (Draco id {unique!r}) is not in its Draco data or "
                                 "names no accessor")
            pointed.append((accessors[accessor], np.ascontiguousarray(found["data"])))
        faces = getattr(mesh, "faces", None)
        if "indices" in primitive and faces is not None and _index_in(primitive["indices"], accessors):
            pointed.append((accessors[primitive["indices"]], np.ascontiguousarray(faces, np.uint32).reshape(-1)))
        del primitive["extensions"][DRACO]
    number = len(buffers)
    for accessor, array in pointed:
        array = array.astype(np.float32) if array.dtype.kind == "f" else array
        if array.dtype not in _DRACO_TYPES:
            array = array.astype(np.uint32 if array.dtype.kind == "u" else np.float32)
        while len(decoded) % 4:
            decoded.append(0)
        views.append({"buffer": number, "byteOffset": len(decoded), "byteLength": array.nbytes})
        decoded.extend(array.tobytes())
        accessor.update(bufferView=len(views) - 1, byteOffset=0, count=len(array),
                        componentType=_DRACO_TYPES[array.dtype])
        accessor.pop("normalized", None)  # (decoded to the values themselves)
        accessor.pop("sparse", None)
        if array.ndim == 2 and "min" in accessor:  # (a position's box, as decoded)
            accessor["min"], accessor["max"] = array.min(axis=0).tolist(), array.max(axis=0).tolist()
    buffers.append({"byteLength": len(decoded),
                    "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(decoded)).decode("ascii")})
    return len(coded)


def _view_bytes(view: dict, buffer_bytes: BufferBytes, label: str) -> bytes | memoryview:
    """A bufferView's bytes, checked against its buffer."""
    buffer, offset, length = view.get("buffer"), view.get("byteOffset", 0), view.get("byteLength")
    source = buffer_bytes(buffer) if isinstance(buffer, int) and not isinstance(buffer, bool) else None
    if source is None or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (offset, length)) \
            or offset + length > len(source):
        raise AssetError(f"{label}: its bufferView lies outside its buffer")
    return source[offset:offset + length]


def _index_in(index: object, items: list) -> bool:
    return isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(items)


def decode_meshopt_views(doc: dict, buffer_bytes: BufferBytes, what: str) -> int:
    """Decode every bufferView ``EXT_meshopt_compression`` packs into a new buffer (appended
    to ``doc["buffers"]`` as base64 data) and point the view at it; how many were decoded.
    Without the meshopt package (the file only uses the extension: its fallback buffer holds
    the data) nothing is done.  A view whose compressed bytes lie outside its buffer, or
    whose mode, filter, count or stride are not the extension's, or whose data does not
    decode, is an AssetError naming it."""
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    packed = [(i, view) for i, view in enumerate(views) if isinstance(view, dict)
              and isinstance(view.get("extensions"), dict) and MESHOPT in view["extensions"]]
    meshopt = _decoder(MESHOPT) if packed else None
    if meshopt is None:
        return 0
    decoded = bytearray()
    placed: list[tuple[dict, int, int]] = []
    for index, view in packed:
        label = f"{what}: bufferView {index} ({MESHOPT})"
        ext = view["extensions"][MESHOPT]
        if not isinstance(ext, dict):
            raise AssetError(f"{label}: must be an object, got {ext!r}")
        count, stride, mode = ext.get("count"), ext.get("byteStride"), ext.get("mode")
        filter_ = ext.get("filter", "NONE")
        offset, length, buffer = ext.get("byteOffset", 0), ext.get("byteLength"), ext.get("buffer")
        for name, value in (("count", count), ("byteStride", stride), ("byteLength", length), ("buffer", buffer),
                            ("byteOffset", offset)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise AssetError(f"{label}: {name} must be a whole number >= 0, got {value!r}")
        if mode not in MESHOPT_MODES or filter_ not in MESHOPT_FILTERS:
            raise AssetError(f"{label}: mode must be one of {MESHOPT_MODES} and filter one of {MESHOPT_FILTERS}, "
                             f"got {mode!r} and {filter_!r}")
        if (mode == "ATTRIBUTES" and not (stride % 4 == 0 and 4 <= stride <= 256)) or \
                (mode != "ATTRIBUTES" and stride not in (2, 4)):
            raise AssetError(f"{label}: byteStride {stride} does not suit mode {mode} (attributes: a multiple of 4 "
                             "up to 256; triangles and indices: 2 or 4)")
        if count * stride != view.get("byteLength"):
            # (checked before decoding: the decoder allocates count x byteStride bytes, which a
            # spoilt count makes gigabytes, zeroed for tens of seconds before it fails)
            raise AssetError(f"{label}: count x byteStride is {count * stride} bytes, but the view's byteLength is "
                             f"{view.get('byteLength')!r} (the extension decodes to the view's length)")
        if count * stride > ASSET_MEMORY_BUDGET:
            raise AssetError(f"{label}: decodes to {count * stride} bytes, past the {ASSET_MEMORY_BUDGET}-byte "
                             "budget of one asset's arrays")
        source = buffer_bytes(buffer)
        if source is None or offset + length > len(source):
            raise AssetError(f"{label}: its {length} bytes at {offset} lie outside buffer {buffer}")
        try:
            plain = meshopt.decode_gltf_buffer(bytes(source[offset:offset + length]), count, stride, mode,
                                               None if filter_ == "NONE" else filter_)
        except (ValueError, RuntimeError) as exc:
            raise AssetError(f"{label}: its data does not decode ({exc})") from None
        data = plain.tobytes()
        if len(data) != count * stride:
            raise AssetError(f"{label}: decoded to {len(data)} bytes, not count x byteStride = {count * stride}")
        while len(decoded) % 4:
            decoded.append(0)
        placed.append((view, len(decoded), len(data)))
        decoded.extend(data)
    buffers = doc.setdefault("buffers", [])
    for buffer in buffers:  # a fallback buffer holds nothing: no view reads it now
        extensions = buffer.get("extensions") if isinstance(buffer, dict) else None
        if isinstance(extensions, dict) and isinstance(extensions.get(MESHOPT), dict) and "uri" not in buffer:
            buffer.update(byteLength=0, uri="data:application/octet-stream;base64,")
            del extensions[MESHOPT]
    number = len(buffers)
    buffers.append({"byteLength": len(decoded),
                    "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(decoded)).decode("ascii")})
    for view, offset, length in placed:
        view.update(buffer=number, byteOffset=offset, byteLength=length)
        del view["extensions"][MESHOPT]
    return len(placed)


def decode_basisu_textures(doc: dict, image_bytes: Callable[[int], bytes | memoryview | None], what: str) -> int:
    """Point each texture whose ``KHR_texture_basisu`` names a KTX2 image at that image
    transcoded to PNG (a ``data:`` URI in its place); how many were.  ``image_bytes(i)``:
    image i's bytes (its file's or its view's; None: none).  Without the alktx2 package (the
    file only uses the extension: its textures keep their PNG or JPEG ``source``) nothing is
    done.  A KTX2 image the texture names that the file lacks, or that does not transcode, is
    an AssetError naming it."""
    textures = doc.get("textures") if isinstance(doc.get("textures"), list) else []
    named = [(i, t["extensions"][BASISU]) for i, t in enumerate(textures) if isinstance(t, dict)
             and isinstance(t.get("extensions"), dict) and BASISU in t["extensions"]]
    alktx2 = _decoder(BASISU) if named else None
    if alktx2 is None:
        return 0
    images = doc.get("images") if isinstance(doc.get("images"), list) else []
    done: dict[int, int] = {}
    for index, ext in named:
        source = ext.get("source") if isinstance(ext, dict) else None
        label = f"{what}: texture {index} ({BASISU})"
        if isinstance(source, bool) or not isinstance(source, int) or not 0 <= source < len(images):
            raise AssetError(f"{label}: names image {source!r}, which the file does not have")
        if source not in done:
            data = image_bytes(source)
            if data is None:
                raise AssetError(f"{label}: image {source} has no data")
            try:
                png, _ = alktx2.decode_ktx2_to_bytes(bytes(data), format="png", lossless=True)
            except Exception as exc:  # (the transcoder's own errors: a malformed KTX2)
                raise AssetError(f"{label}: image {source} is not a KTX2 image Basis Universal can read "
                                 f"({type(exc).__name__}: {exc})") from None
            images[source] = {"uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii"),
                              "mimeType": "image/png"}
            done[source] = source
        textures[index]["source"] = source
        del textures[index]["extensions"][BASISU]
    return len(named)
