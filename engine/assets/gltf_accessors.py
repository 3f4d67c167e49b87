"""glTF accessors of normalised integers (``"normalized": true``) made floats, and sparse
accessors made dense, before trimesh reads them.

glTF stores texture coordinates and vertex colours as normalised bytes or shorts where an
exporter packs them (core glTF allows it for ``TEXCOORD_n`` and ``COLOR_n``), and
``KHR_mesh_quantization`` (gltfpack's and glTF-Transform's output) does so for normals,
tangents and coordinates too: 65535 in an unsigned short means 1.0, -127 in a signed byte
-1.0.  trimesh reads the integers as they are (a UV of 65535, then flipped in place as an
integer, so every UV comes out wrong without a word).  Here each such accessor is decoded
(its view's stride and offsets checked against its buffer) into float32 values in a buffer
of the engine's making, a ``data:`` URI, and the accessor is pointed at it, so trimesh reads
what the file means.  Integers that are not normalised (a quantized position, moved into
place by its node's scale) are left alone: trimesh reads them as the numbers they are.
"""
from __future__ import annotations

import base64
from collections.abc import Callable

import numpy as np

from engine.core.errors import AssetError

# componentType -> (numpy type, the integer that means 1.0); glTF's rule for signed ones:
# max(c / max, -1.0)
NORMALIZED_TYPES = {5120: (np.int8, 127.0), 5121: (np.uint8, 255.0), 5122: (np.int16, 32767.0),
                    5123: (np.uint16, 65535.0)}
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}  # (a float MAT4 has no padding)
FLOAT = 5126
# A file's buffer by index: its bytes as read (a view of a GLB's binary chunk), None where it has none
BufferBytes = Callable[[int], "bytes | memoryview | None"]


def float_normalized_accessors(doc: dict, buffer_bytes: BufferBytes, what: str) -> int:
    """Rewrite ``doc``'s normalised integer accessors as float32 ones reading a new buffer
    (appended to ``doc["buffers"]`` as base64 data); ``buffer_bytes(i)`` is buffer i's
    bytes as read.  How many were rewritten.  An accessor that cannot be read as it says (a
    normalised float, a sparse one, a view or buffer it does not have, values past the end of
    its view) is an AssetError naming it."""
    accessors = doc.get("accessors")
    if not isinstance(accessors, list):
        return 0
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    decoded = bytearray()
    new_views: list[dict] = []
    rewritten: list[tuple[dict, int]] = []
    for index, accessor in enumerate(accessors):
        if not isinstance(accessor, dict) or accessor.get("normalized") is not True:
            continue
        label = f"{what}: accessor {index}"
        values = _decode(accessor, views, buffer_bytes, label)
        while len(decoded) % 4:
            decoded.append(0)
        new_views.append({"byteOffset": len(decoded), "byteLength": values.nbytes})
        decoded.extend(values.tobytes())
        rewritten.append((accessor, len(new_views) - 1))
    if not rewritten:
        return 0
    buffers = doc.setdefault("buffers", [])
    buffer_index = len(buffers)
    buffers.append({"byteLength": len(decoded),
                    "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(decoded)).decode("ascii")})
    first_view = len(views)
    for view in new_views:
        views.append({"buffer": buffer_index, **view})
    doc["bufferViews"] = views
    for accessor, view in rewritten:
        ctype = accessor["componentType"]
        _, one = NORMALIZED_TYPES[ctype]
        for key in ("min", "max"):  # in the component type's integers: as the values, in floats
            if isinstance(accessor.get(key), list):
                accessor[key] = [max(float(v) / one, -1.0) for v in accessor[key]]
        accessor.update(bufferView=first_view + view, byteOffset=0, componentType=FLOAT)
        del accessor["normalized"]
    return len(rewritten)


# componentType -> numpy type, every kind an accessor may hold
COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                   5126: np.float32}
INDEX_TYPES = (5121, 5123, 5125)  # what a sparse accessor's indices may be


def dense_sparse_accessors(doc: dict, buffer_bytes: BufferBytes, what: str) -> int:
    """Rewrite ``doc``'s sparse accessors (a base, its bufferView's values or zeros, with some
    elements replaced: glTF's way to store a morph target that moves a few vertices) as dense
    ones reading a new buffer, as ``float_normalized_accessors`` does; trimesh reads a sparse
    accessor's base alone, zeros where it has none, without a word.  How many were
    rewritten; one that cannot be read (indices out of range or not increasing, a view past
    its buffer) is an AssetError naming it.  Run before ``float_normalized_accessors``: a
    normalised one stays normalised, dense."""
    accessors = doc.get("accessors")
    if not isinstance(accessors, list):
        return 0
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    decoded = bytearray()
    rewritten: list[tuple[dict, int, int]] = []
    for index, accessor in enumerate(accessors):
        if not isinstance(accessor, dict) or "sparse" not in accessor:
            continue
        label = f"{what}: accessor {index}"
        values = _dense(accessor, views, buffer_bytes, label)
        while len(decoded) % 4:
            decoded.append(0)
        rewritten.append((accessor, len(decoded), values.nbytes))
        decoded.extend(values.tobytes())
    if not rewritten:
        return 0
    buffers = doc.setdefault("buffers", [])
    buffers.append({"byteLength": len(decoded),
                    "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(decoded)).decode("ascii")})
    for accessor, offset, length in rewritten:
        views.append({"buffer": len(buffers) - 1, "byteOffset": offset, "byteLength": length})
        accessor.update(bufferView=len(views) - 1, byteOffset=0)
        del accessor["sparse"]
    doc["bufferViews"] = views
    return len(rewritten)


def check_accessor_views(doc: dict, buffer_bytes: BufferBytes, what: str) -> None:
    """Every dense accessor's elements inside its bufferView and that view inside its buffer's
    bytes as read, before trimesh reads them: a GLB or ``.bin`` cut short, a GLB without its
    binary chunk, a view naming a buffer the file lacks or a count past its view is an
    AssetError naming the accessor and why (trimesh fails on them with a bare IndexError,
    ValueError or AssertionError).  Run after ``dense_sparse_accessors``."""
    accessors = doc.get("accessors")
    if not isinstance(accessors, list):
        return
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    buffers = doc.get("buffers") if isinstance(doc.get("buffers"), list) else []
    for index, accessor in enumerate(accessors):
        if not isinstance(accessor, dict) or "bufferView" not in accessor or "sparse" in accessor:
            continue
        label = f"{what}: accessor {index}"
        ctype, kind, count = accessor.get("componentType"), accessor.get("type"), accessor.get("count")
        if ctype not in COMPONENT_TYPES or kind not in COMPONENTS or isinstance(count, bool) \
                or not isinstance(count, int) or count < 1:
            continue  # (not an accessor of a kind read here: trimesh's to refuse)
        view_index = accessor["bufferView"]
        if isinstance(view_index, bool) or not isinstance(view_index, int) or not 0 <= view_index < len(views) \
                or not isinstance(views[view_index], dict):
            raise AssetError(f"{label}: names bufferView {view_index!r}, which the file does not have")
        view = views[view_index]
        buffer_index = view.get("buffer")
        if isinstance(buffer_index, bool) or not isinstance(buffer_index, int) or not 0 <= buffer_index < len(buffers):
            raise AssetError(f"{label}: its bufferView {view_index} names buffer {buffer_index!r}, which the file "
                             "does not have")
        data = buffer_bytes(buffer_index)
        if data is None:
            raise AssetError(f"{label}: its bufferView {view_index} reads buffer {buffer_index}, whose bytes the "
                             "file does not hold (a GLB without its binary chunk, or data that is not base64)")
        element = np.dtype(COMPONENT_TYPES[ctype]).itemsize * COMPONENTS[kind]
        stride, view_offset = view.get("byteStride", element), view.get("byteOffset", 0)
        view_length, offset = view.get("byteLength"), accessor.get("byteOffset", 0)
        if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0
                   for n in (stride, view_offset, view_length, offset)):
            raise AssetError(f"{label}: its offsets, length and stride ({offset!r}, {view_offset!r}, "
                             f"{view_length!r}, {stride!r}) must be whole numbers >= 0")
        if view_offset + view_length > len(data):
            raise AssetError(f"{label}: its bufferView {view_index} ({view_length} bytes at {view_offset}) runs past "
                             f"the end of buffer {buffer_index}, which holds {len(data)} bytes (the file is cut short)")
        if offset + max(stride, element) * (count - 1) + element > view_length:
            raise AssetError(f"{label}: its {count} elements run past the end of bufferView {view_index}")


def _dense(accessor: dict, views: list, buffer_bytes: BufferBytes, label: str) -> np.ndarray:
    """A sparse accessor's elements, its base with the sparse ones put in (its own type)."""
    ctype, kind, count = accessor.get("componentType"), accessor.get("type"), accessor.get("count")
    if ctype not in COMPONENT_TYPES or kind not in COMPONENTS or kind == "MAT4":
        raise AssetError(f"{label}: a sparse accessor of componentType {ctype!r} and type {kind!r} is not read")
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise AssetError(f"{label}: count must be an integer >= 1, got {count!r}")
    dtype, width = COMPONENT_TYPES[ctype], COMPONENTS[kind]
    if "bufferView" in accessor:
        base = {key: value for key, value in accessor.items() if key != "sparse"}
        values = _read(base, views, buffer_bytes, label, dtype).copy()
    else:
        values = np.zeros((count, width), dtype)
    sparse = accessor["sparse"]
    if not isinstance(sparse, dict) or not isinstance(sparse.get("indices"), dict) \
            or not isinstance(sparse.get("values"), dict):
        raise AssetError(f"{label}: sparse must hold a count, indices and values, got {sparse!r}")
    replaced = sparse.get("count")
    if isinstance(replaced, bool) or not isinstance(replaced, int) or not 1 <= replaced <= count:
        raise AssetError(f"{label}: sparse.count must be an integer in 1..{count}, got {replaced!r}")
    indices_info, values_info = sparse["indices"], sparse["values"]
    if indices_info.get("componentType") not in INDEX_TYPES:
        raise AssetError(f"{label}: sparse.indices.componentType must be an unsigned byte, short or int, got "
                         f"{indices_info.get('componentType')!r}")
    indices = _read({"bufferView": indices_info.get("bufferView"), "byteOffset": indices_info.get("byteOffset", 0),
                     "count": replaced, "type": "SCALAR"}, views, buffer_bytes, f"{label}: sparse.indices",
                    COMPONENT_TYPES[indices_info["componentType"]]).reshape(-1).astype(np.int64)
    if (np.diff(indices) <= 0).any() or indices.min() < 0 or indices.max() >= count:
        raise AssetError(f"{label}: sparse.indices must increase and lie in 0..{count - 1}")
    where = {"bufferView": values_info.get("bufferView"), "byteOffset": values_info.get("byteOffset", 0),
             "count": replaced, "type": kind}
    values[indices] = _read(where, views, buffer_bytes, f"{label}: sparse.values", dtype)
    if dtype is np.float32 and not np.isfinite(values).all():
        raise AssetError(f"{label}: holds NaN or infinite values")
    return values


def _read(accessor: dict, views: list, buffer_bytes: BufferBytes, label: str, dtype) -> np.ndarray:
    """A dense accessor's elements as they are stored (one row an element)."""
    return _decode(accessor, views, buffer_bytes, label, (dtype, None))


def read_float_accessor(doc: dict, index: object, buffer_bytes: BufferBytes, label: str) -> np.ndarray:
    """Accessor ``index`` of ``doc`` as float32 rows, one an element: a float accessor's values
    or a normalised one's (run ``float_normalized_accessors`` first, or not); anything else is
    an AssetError naming it."""
    accessors = doc.get("accessors") if isinstance(doc.get("accessors"), list) else []
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(accessors) \
            or not isinstance(accessors[index], dict):
        raise AssetError(f"{label}: names accessor {index!r}, which the file does not have")
    accessor = accessors[index]
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    if accessor.get("normalized") is True:
        return _decode(accessor, views, buffer_bytes, f"{label}: accessor {index}")
    if accessor.get("componentType") != FLOAT:
        raise AssetError(f"{label}: accessor {index} must hold floats (or normalised integers), got componentType "
                         f"{accessor.get('componentType')!r}")
    return _decode(accessor, views, buffer_bytes, f"{label}: accessor {index}", (np.float32, 1.0))


def _decode(accessor: dict, views: list, buffer_bytes: BufferBytes, label: str,
            float_type: tuple | None = None) -> np.ndarray:
    """A normalised accessor's values as float32, one row an element (``float_type``: a
    float accessor's, read as they are)."""
    ctype, kind, count = accessor.get("componentType"), accessor.get("type"), accessor.get("count")
    if float_type is None and ctype not in NORMALIZED_TYPES:
        raise AssetError(f"{label}: normalized is only for byte and short components (glTF), got componentType "
                         f"{ctype!r}")
    if kind not in COMPONENTS:
        raise AssetError(f"{label}: an accessor of type {kind!r} is not read here (SCALAR, VEC2-4 or MAT4)")
    if kind == "MAT4" and float_type is None:
        raise AssetError(f"{label}: a normalized MAT4 is not read (its columns are padded; glTF's matrices are floats)")
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise AssetError(f"{label}: count must be an integer >= 1, got {count!r}")
    if "sparse" in accessor:
        raise AssetError(f"{label}: a sparse accessor is read once made dense (dense_sparse_accessors)")
    view_index = accessor.get("bufferView")
    if isinstance(view_index, bool) or not isinstance(view_index, int) or not 0 <= view_index < len(views) \
            or not isinstance(views[view_index], dict):
        raise AssetError(f"{label}: names bufferView {view_index!r}, which the file does not have")
    view = views[view_index]
    buffer_index = view.get("buffer")
    data = buffer_bytes(buffer_index) if isinstance(buffer_index, int) and not isinstance(buffer_index, bool) else None
    if data is None:
        raise AssetError(f"{label}: its bufferView {view_index} names buffer {buffer_index!r}, which the file does "
                         "not have")
    dtype, one = float_type or NORMALIZED_TYPES[ctype]
    size = np.dtype(dtype).itemsize
    components = COMPONENTS[kind]
    element = size * components
    stride = view.get("byteStride", element)
    view_offset, view_length = view.get("byteOffset", 0), view.get("byteLength")
    offset = accessor.get("byteOffset", 0)
    numbers = (stride, view_offset, view_length, offset)
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in numbers) or stride < element \
            or offset % size or (view_offset + offset) % size or stride % size:
        raise AssetError(f"{label}: its offsets and stride ({offset!r}, {view_offset!r}, {stride!r}) do not fit "
                         f"its {np.dtype(dtype).name} elements")
    end = offset + stride * (count - 1) + element
    if end > view_length or view_offset + view_length > len(data):
        raise AssetError(f"{label}: its {count} elements run past the end of bufferView {view_index}")
    raw = np.ndarray((count, components), dtype, buffer=data, offset=view_offset + offset, strides=(stride, size))
    if float_type is not None and one is None:  # (as stored: _read)
        return np.array(raw)
    if float_type is not None:
        values = raw.astype(np.float32)
        if not np.isfinite(values).all():
            raise AssetError(f"{label}: holds NaN or infinite values")
        return values
    return np.maximum(raw.astype(np.float32) / np.float32(one), np.float32(-1.0))
