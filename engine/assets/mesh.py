"""Mesh data on the CPU, the built-in primitives, and loading mesh files through trimesh.

A Mesh is plain arrays; the renderer uploads it once and shares it between every entity
whose MeshRef points at it.
"""
from __future__ import annotations

import contextlib
import itertools
import json
import logging
import math
import numbers
import os
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from pyglm import glm

from engine.assets.texture_data import (
    TextureData,
    check_asset_file,
    check_texture_size,
    contained_path,
    height_to_normal_map,
    image_to_rgba8,
    is_grey,
    load_texture,
    pillow_image_module,
)
from engine.core.errors import AssetError

if TYPE_CHECKING:  # trimesh is imported when a mesh file is first loaded
    import trimesh

_mesh_ids = itertools.count(1)


@dataclass(eq=False)
class Mesh:
    """Indexed triangles: positions, normals (unit), uvs, and int32 triangle indices."""

    ASSET_KIND = "mesh"  # what MeshRef.mesh checks for (components do not import the engine)

    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    indices: np.ndarray
    name: str = "mesh"
    id: int = field(default_factory=lambda: next(_mesh_ids))
    # How it was made, as a level file writes it ({"box": [w, h, d]}, {"file": path}, ...);
    # None for a mesh built from arrays, which a level file cannot name.
    source: dict | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, np.float32).reshape(-1, 3)
        self.normals = np.ascontiguousarray(self.normals, np.float32).reshape(-1, 3)
        self.uvs = np.ascontiguousarray(self.uvs, np.float32).reshape(-1, 2)
        self.indices = np.ascontiguousarray(self.indices, np.int32).reshape(-1, 3)
        n = len(self.positions)
        if n == 0 or len(self.indices) == 0:
            raise AssetError(f"mesh {self.name!r}: has no triangles")
        if len(self.normals) != n or len(self.uvs) != n:
            raise AssetError(f"mesh {self.name!r}: {n} positions but {len(self.normals)} normals and "
                             f"{len(self.uvs)} uvs")
        if not (np.isfinite(self.positions).all() and np.isfinite(self.normals).all()
                and np.isfinite(self.uvs).all()):
            raise AssetError(f"mesh {self.name!r}: has NaN or infinite vertex data")
        if self.indices.min() < 0 or self.indices.max() >= n:
            raise AssetError(f"mesh {self.name!r}: triangle index out of range 0..{n - 1}")

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Model-space AABB (min, max)."""
        return self.positions.min(axis=0), self.positions.max(axis=0)

    def interleaved(self) -> np.ndarray:
        """Vertex buffer contents: position, normal, uv per vertex (8 floats)."""
        return np.hstack([self.positions, self.normals, self.uvs]).astype(np.float32)

    @classmethod
    def from_trimesh(cls, tm: trimesh.Trimesh, name: str = "mesh") -> Mesh:
        """Convert a trimesh.Trimesh (its UVs are used when it has them)."""
        uv = getattr(getattr(tm, "visual", None), "uv", None)
        positions = np.asarray(tm.vertices, np.float32)
        if len(positions) == 0 or len(tm.faces) == 0:
            raise AssetError(f"mesh {name!r}: has no triangles")
        if uv is None or len(uv) != len(positions):
            uv = np.zeros((len(positions), 2), np.float32)
        if not np.isfinite(positions).all():
            raise AssetError(f"mesh {name!r}: has NaN or infinite vertex data")
        faces = np.asarray(tm.faces)
        if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
            raise AssetError(f"mesh {name!r}: faces are not triangles of vertex indices (shape {faces.shape})")
        low, high = int(faces.min()), int(faces.max())
        if low < 0 or high >= len(positions):  # before normals are worked out from them
            raise AssetError(f"mesh {name!r}: face index {low if low < 0 else high} is out of range "
                             f"({len(positions)} vertices)")
        return cls(positions, _unit_normals(tm), uv, faces, name=name)


def _unit_normals(tm) -> np.ndarray:
    """The file's vertex normals made unit length; zero or broken ones are recomputed from the faces."""
    normals = np.asarray(tm.vertex_normals, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        length = np.linalg.norm(normals, axis=1)
        bad = ~np.isfinite(length) | (length < 1e-12)
        normals = normals / np.where(bad, 1.0, length)[:, None]
    if bad.any():
        import trimesh

        faces = np.asarray(tm.faces)
        with np.errstate(invalid="ignore", divide="ignore"):
            face_normals, valid = trimesh.triangles.normals(np.asarray(tm.vertices, np.float64)[faces])
        fallback = np.zeros((len(faces), 3))
        fallback[valid] = face_normals
        computed = trimesh.geometry.mean_vertex_normals(len(normals), faces, fallback)
        normals[bad] = computed[bad]
        still_bad = ~np.isfinite(normals).all(axis=1) | (np.linalg.norm(normals, axis=1) < 1e-6)
        normals[still_bad] = (0.0, 0.0, 1.0)  # vertices of degenerate triangles only
    return normals.astype(np.float32)


FLATNESS = 1e-4  # an AABB extent below this fraction of the largest counts as flat


def flat_plane(mesh: Mesh) -> tuple[np.ndarray, np.ndarray] | None:
    """The flatness test: a mesh is planar when one extent of its AABB is ~0; the plane's
    normal is the mesh's (mean) normal along that axis. None when the mesh is not flat."""
    positions, normals = mesh.positions, mesh.normals
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    extent = hi - lo
    axis = int(np.argmin(extent))
    if extent[axis] > FLATNESS * max(float(extent.max()), 1e-9):
        return None
    normal = normals.mean(axis=0)
    if abs(normal[axis]) < 0.5 * np.linalg.norm(normal) or np.linalg.norm(normal) < 1e-6:
        return None
    direction = np.zeros(3)
    direction[axis] = np.sign(normal[axis])
    return (lo + hi) / 2.0, direction


# --- primitives --------------------------------------------------------------------------

def _extent(value, what: str, mesh: str) -> float:
    """A generator's size: a finite number >= 0 (0 is a mesh with no area, which a mirror or
    portal refuses; a negative one would turn the mesh inside out)."""
    if isinstance(value, (bool, str, bytes)) or not isinstance(value, numbers.Real) or \
            not (math.isfinite(float(value)) and 0.0 <= float(value) <= MAX_EXTENT):
        raise AssetError(f"{mesh}: {what} must be a finite number >= 0 (at most {MAX_EXTENT:g}), got {value!r}")
    return float(value)


def _name(name, kind: str) -> str:
    if not isinstance(name, str):
        raise AssetError(f"{kind} mesh: name must be a string, got {name!r}")
    return name


MAX_EXTENT = 1e18  # metres: a generated mesh's size (past float32 once scaled and multiplied out)


def box(size: tuple[float, float, float] = (1.0, 1.0, 1.0), name: str = "box") -> Mesh:
    """An axis-aligned box centred on the origin, flat normals, 0..1 UVs per face; ``size``
    is three finite numbers >= 0."""
    name = _name(name, "box")
    if isinstance(size, (str, bytes)) or not hasattr(size, "__len__") or len(size) != 3:
        raise AssetError(f"box mesh {name!r}: size must be three numbers [w, h, d], got {size!r}")
    hx, hy, hz = (_extent(s, "size", f"box mesh {name!r}") * 0.5 for s in size)
    positions, normals, uvs, indices = [], [], [], []
    faces = [  # normal, u axis, v axis
        ((1, 0, 0), (0, 0, -1), (0, 1, 0)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, -1)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
    ]
    half = np.array([hx, hy, hz])
    for n, u, v in faces:
        n, u, v = np.array(n, float), np.array(u, float), np.array(v, float)
        base = len(positions)
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            positions.append((n + su * u + sv * v) * half)
            normals.append(n)
            uvs.append(((su + 1) / 2, (sv + 1) / 2))
        indices += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return Mesh(np.array(positions), np.array(normals), np.array(uvs), np.array(indices), name=name,
                source={"box": [float(s) for s in size], **({} if name == "box" else {"name": name})})


def plane(width: float = 1.0, depth: float = 1.0, uv_repeat: float = 1.0, name: str = "plane") -> Mesh:
    """A flat rectangle in the XZ plane facing +Y; sizes finite and >= 0, ``uv_repeat`` (the
    UVs run 0..uv_repeat) any finite number."""
    name = _name(name, "plane")
    width, depth = _extent(width, "width", f"plane mesh {name!r}"), _extent(depth, "depth", f"plane mesh {name!r}")
    if isinstance(uv_repeat, (bool, str, bytes)) or not isinstance(uv_repeat, numbers.Real) or \
            not abs(float(uv_repeat)) <= MAX_UV_REPEAT:
        raise AssetError(f"plane mesh {name!r}: uv_repeat must be a finite number (at most {MAX_UV_REPEAT:g} either "
                         f"way), got {uv_repeat!r}")
    uv_repeat = float(uv_repeat)
    hw, hd = width / 2, depth / 2
    positions = np.array([(-hw, 0, hd), (hw, 0, hd), (hw, 0, -hd), (-hw, 0, -hd)])
    normals = np.tile((0.0, 1.0, 0.0), (4, 1))
    uvs = np.array([(0, 0), (1, 0), (1, 1), (0, 1)]) * uv_repeat
    source = {"plane": [float(width), float(depth)], **({} if uv_repeat == 1.0 else {"uv_repeat": float(uv_repeat)}),
              **({} if name == "plane" else {"name": name})}
    return Mesh(positions, normals, uvs, np.array([(0, 1, 2), (0, 2, 3)]), name=name, source=source)


MAX_UV_REPEAT = 1e6  # past it float32 UVs have no texel left between neighbours


def quad(width: float = 1.0, height: float = 1.0, name: str = "quad") -> Mesh:
    """A flat rectangle in the XY plane facing +Z (mirrors and portals use it); sizes finite
    and >= 0."""
    name = _name(name, "quad")
    width, height = _extent(width, "width", f"quad mesh {name!r}"), _extent(height, "height", f"quad mesh {name!r}")
    hw, hh = width / 2, height / 2
    positions = np.array([(-hw, -hh, 0), (hw, -hh, 0), (hw, hh, 0), (-hw, hh, 0)])
    normals = np.tile((0.0, 0.0, 1.0), (4, 1))
    uvs = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
    return Mesh(positions, normals, uvs, np.array([(0, 1, 2), (0, 2, 3)]), name=name,
                source={"quad": [float(width), float(height)], **({} if name == "quad" else {"name": name})})


MAX_SPHERE_DIVISIONS = 1024  # segments or rings of a generated sphere (a million triangles at most)


def sphere(radius: float = 0.5, segments: int = 48, rings: int = 24, name: str = "sphere") -> Mesh:
    """A UV sphere with smooth normals; ``radius`` finite and >= 0. Built in float32 and
    int32 in place: it allocates about the mesh it returns (56 MB at 1024 x 1024)."""
    name = _name(name, "sphere")
    radius = _extent(radius, "radius", f"sphere mesh {name!r}")
    for what, value, low in (("segments", segments, 3), ("rings", rings, 2)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= MAX_SPHERE_DIVISIONS:
            raise AssetError(f"sphere mesh {name!r}: {what} must be an int in [{low}, {MAX_SPHERE_DIVISIONS}], "
                             f"got {value!r}")
    theta = np.linspace(0.0, np.pi, rings + 1)[:, np.newaxis]      # from +Y down, one per row
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)[np.newaxis, :]
    row = segments + 1
    count = (rings + 1) * row
    normals = np.empty((rings + 1, row, 3), np.float32)
    positions = np.empty((rings + 1, row, 3), np.float32)
    for axis, part in enumerate((lambda: np.sin(theta) * np.sin(phi), lambda: np.cos(theta) + 0.0 * phi,
                                 lambda: np.sin(theta) * np.cos(phi))):
        value = part()  # one coordinate in float64 at a time: positions are float32(normal * radius) exactly
        normals[..., axis] = value
        value *= radius
        positions[..., axis] = value
    uvs = np.empty((rings + 1, row, 2), np.float32)
    uvs[..., 0] = phi / (2 * np.pi)
    uvs[..., 1] = 1.0 - theta / np.pi
    a = (np.arange(rings, dtype=np.int32)[:, np.newaxis] * row + np.arange(segments, dtype=np.int32)).ravel()
    indices = np.empty((2, len(a), 3), np.int32)
    indices[0, :, 0] = indices[1, :, 0] = a
    indices[0, :, 1] = a + row
    indices[0, :, 2] = indices[1, :, 1] = a + row + 1
    indices[1, :, 2] = a + 1
    source = {"sphere": float(radius), **({} if segments == 48 else {"segments": int(segments)}),
              **({} if rings == 24 else {"rings": int(rings)}), **({} if name == "sphere" else {"name": name})}
    return Mesh(positions.reshape(count, 3), normals.reshape(count, 3), uvs.reshape(count, 2), indices.reshape(-1, 3),
                name=name,
                source=source)


# --- loading files -----------------------------------------------------------------------

@dataclass
class ModelPart:
    """One mesh of a loaded file with the material the file gave it.

    The maps are ``Material``'s: ``normal_map`` (glTF's ``normalTexture`` with its
    ``scale``; an MTL's ``norm``, or ``map_Bump`` / ``bump``, a grey one being a height map
    turned into normals, with ``-bm`` as the scale), ``emissive_map`` (glTF's
    ``emissiveTexture``, an MTL's ``map_Ke``) and ``metallic_roughness_map`` (glTF's
    ``metallicRoughnessTexture``).  With an emissive map, ``emissive_factor`` is the
    strength the map is emitted at (the largest channel of glTF's ``emissiveFactor`` or the
    MTL's ``Ke``; a factor that is not grey has its hue multiplied into the map's texels),
    not the ratio of emissive to diffuse colour it is without one."""

    mesh: Mesh
    local: glm.mat4
    color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: TextureData | None = None
    metallic: float = 0.0
    roughness: float = 0.5
    emissive_factor: float = 0.0   # emissive colour / diffuse colour (with an emissive map: its strength)
    reflectivity: float = 0.0
    normal_map: TextureData | None = None
    normal_scale: float = 1.0
    emissive_map: TextureData | None = None
    metallic_roughness_map: TextureData | None = None


SUPPORTED_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")
MAX_MESH_FILE_BYTES = 256 << 20  # a mesh file's size: trimesh holds several times it while parsing
MAX_JSON_NESTING = 64  # arrays and objects inside a glTF's JSON (a real one nests about 6 deep)


def load_model(path: str | Path, roots: Sequence[str | Path] | None = None) -> list[ModelPart]:
    """Load every mesh of a file with trimesh; errors name the file and the reason.

    The file, and every file it names (an OBJ's material libraries and their images, a
    glTF's buffers and images), must be a regular file (a FIFO, a device or a directory is
    refused before anything opens it); ``roots``: folders those named files must be inside
    (a level's folder and asset roots; None, anywhere). A file past MAX_MESH_FILE_BYTES,
    JSON nested past MAX_JSON_NESTING, an image past the texture limits, or running out of
    memory is an AssetError too."""
    import trimesh

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"mesh file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    path = Path(path)
    what = f"mesh file {str(path)!r}"
    info = check_asset_file(path, what, MAX_MESH_FILE_BYTES)
    if path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise AssetError(f"{what}: unsupported type {path.suffix!r} (supported: {', '.join(SUPPORTED_SUFFIXES)})")
    if info.st_size == 0:
        raise AssetError(f"{what}: file is empty")
    Image = pillow_image_module()  # the texture limits for the images trimesh decodes
    try:
        with _quiet_trimesh(), warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            return _load_model(path, what, roots, trimesh)
    except MemoryError:
        raise AssetError(f"{what}: does not fit in memory") from None


def _load_model(path: Path, what: str, roots, trimesh) -> list[ModelPart]:
    suffix = path.suffix.lower()
    gltf_doc = None  # a glTF's JSON: what trimesh does not keep (normalTexture.scale)
    if suffix == ".gltf":
        gltf_doc = _check_gltf_json(path, roots)
    elif suffix == ".glb":
        gltf_doc = _check_glb_json(path, roots)
    elif suffix == ".obj":
        _check_obj_text(path, roots)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except MemoryError:
        raise
    except Exception as exc:  # trimesh raises many kinds for corrupt files
        raise AssetError(f"{what}: cannot be parsed ({type(exc).__name__}: {exc})") from exc
    parts: list[ModelPart] = []
    try:
        texture_refs = _mtl_texture_refs(path) if suffix == ".obj" else {}
        maps = _MaterialMaps(path, gltf_doc, roots)
        for node in loaded.graph.nodes_geometry:
            matrix, geom_name = loaded.graph[node]
            tm = loaded.geometry[geom_name]
            if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
                continue
            matrix = np.asarray(matrix, np.float64)
            if not np.isfinite(matrix).all():
                raise AssetError(f"node {node!r} has a NaN or infinite transform")
            singular = np.linalg.svd(matrix[:3, :3], compute_uv=False)
            if singular[-1] <= 1e-9 * singular[0] or singular[0] == 0.0:
                continue  # scaled to nothing (files hide nodes this way): it would draw nothing
            if np.abs(matrix).max() > 1e18:
                # Past float32 once multiplied out (vertex x scale x parents): refuse here, by node.
                raise AssetError(f"node {node!r} has a transform too large for float32 rendering "
                                 f"(largest entry {np.abs(matrix).max():.3g}, limit 1e18)")
            mesh = Mesh.from_trimesh(tm, name=f"{path.name}:{geom_name}")
            part = ModelPart(mesh=mesh, local=glm.mat4(*matrix.astype(np.float32).T.ravel()))
            _read_material(tm, part, path, texture_refs)
            maps.read(tm, part)
            parts.append(part)
    except AssetError as exc:
        raise AssetError(f"{what}: {exc}") from exc
    except MemoryError:
        raise
    except Exception as exc:  # trimesh computing normals/visuals of malformed data
        raise AssetError(f"{what}: holds malformed mesh data ({type(exc).__name__}: {exc})") from exc
    if not parts:
        raise AssetError(f"{what}: contains no triangle meshes")
    return parts


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """trimesh logs what it works around in a bad file, tracebacks included (Python's last-
    resort handler prints them): the loader says what is wrong itself, in one line."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _referenced(path: Path, name: str, roots, kind: str, owner: str = "mesh file") -> Path | None:
    """A file ``path`` names (``name``, relative to its folder): None when it does not exist
    (the loader says so or does without it); an AssetError when it is outside ``roots`` or
    not a regular file, before anything opens it."""
    target = path.parent / name
    if roots is not None and contained_path(target, roots) is None:
        raise AssetError(f"{owner} {str(path)!r}: its {kind} {name!r} is outside the level's folder (a level's "
                         "assets stay inside it: a game may declare more asset roots, a player may pass "
                         "--asset-root DIR)")
    if not os.path.lexists(target):
        return None
    check_asset_file(target, f"{owner} {str(path)!r}: its {kind} {name!r}")
    return target


def _check_gltf_json(path: Path, roots=None) -> dict:
    """A .gltf is JSON; say so plainly instead of trimesh's guess at a missing buffer file,
    and check the files it names.  Returns the document."""
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except RecursionError:
        raise AssetError(f"mesh file {str(path)!r}: its JSON is nested too deeply (at most {MAX_JSON_NESTING})") \
            from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise AssetError(f"mesh file {str(path)!r}: is not a JSON glTF file ({type(exc).__name__})") from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise AssetError(f"mesh file {str(path)!r}: is not a glTF document (no 'asset' object)")
    _check_gltf_document(path, doc, roots)
    return doc


def _check_glb_json(path: Path, roots=None) -> dict | None:
    """A .glb's JSON chunk (12-byte header, then the chunk's length and type): its nesting and
    the files it names. A file that is not a GLB is left to trimesh to refuse.  Returns the
    document (None where there is none to read)."""
    with path.open("rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
            return None
        length = int.from_bytes(head[12:16], "little")
        if length > MAX_MESH_FILE_BYTES:
            return None
        chunk = f.read(length)
    try:
        doc = json.loads(chunk.decode("utf-8"))
    except RecursionError:
        raise AssetError(f"mesh file {str(path)!r}: its JSON is nested too deeply (at most {MAX_JSON_NESTING})") \
            from None
    except (UnicodeDecodeError, ValueError):
        return None  # trimesh says it cannot be parsed
    if isinstance(doc, dict):
        _check_gltf_document(path, doc, roots)
        return doc
    return None


def _check_gltf_document(path: Path, doc: dict, roots) -> None:
    deepest, stack = 0, [(doc, 1)]
    while stack:
        item, depth = stack.pop()
        deepest = max(deepest, depth)
        if deepest > MAX_JSON_NESTING:
            raise AssetError(f"mesh file {str(path)!r}: its JSON is nested too deeply (at most {MAX_JSON_NESTING})")
        children = item.values() if isinstance(item, dict) else item
        stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    for kind in ("buffers", "images"):
        entries = doc.get(kind)
        for entry in entries if isinstance(entries, list) else ():
            uri = entry.get("uri") if isinstance(entry, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                from urllib.parse import unquote

                _referenced(path, unquote(uri), roots, kind[:-1])


def _check_obj_text(path: Path, roots=None) -> None:
    """What trimesh accepts silently or answers with an IndexError in an OBJ: a face index 0
    or past the vertices so far, a vertex with fewer than three numbers, a missing MTL, a
    non-numeric Kd; and a material library or image outside ``roots`` or not a regular file."""
    counts = {b"v": 0, b"vt": 0, b"vn": 0}
    names = ("vertices", "texture coordinates", "normals")
    kinds = ("face index", "texture coordinate index", "normal index")
    with path.open("rb") as f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            first = line.split(None, 1)[0] if line else b""
            if first in counts:
                counts[first] += 1
                if first == b"v" and len(line.split()) < 4:
                    raise AssetError(f"mesh file {str(path)!r}: line {number}: a vertex is 'v x y z' (three "
                                     f"numbers), got {line.decode('utf-8', 'replace')[:60]!r}")
            elif first == b"f":
                _check_face(path, number, line, counts, names, kinds)
            elif first == b"mtllib":
                for name in line[6:].decode("utf-8", "replace").split():
                    library = _referenced(path, name, roots, "material library")
                    if library is None:
                        warnings.warn(f"mesh file {str(path)!r}: material library {name!r} not found; "
                                      f"default material used", stacklevel=4)
                        continue
                    _check_mtl_numbers(library)
                    _check_mtl_files(path, library, roots)


def _check_face(path: Path, number: int, line: bytes, counts: dict, names: tuple, kinds: tuple) -> None:
    for token in line.split()[1:]:
        for slot, (value, key) in enumerate(zip(token.split(b"/"), (b"v", b"vt", b"vn"), strict=False)):
            if not value:
                continue
            try:
                index = int(value)
            except ValueError:
                raise AssetError(f"mesh file {str(path)!r}: line {number}: a face index is a number, got "
                                 f"{value.decode('utf-8', 'replace')[:20]!r}") from None
            if index == 0:
                raise AssetError(f"mesh file {str(path)!r}: line {number}: face index 0 (OBJ indices start at 1)")
            if not -counts[key] <= index <= counts[key]:
                raise AssetError(f"mesh file {str(path)!r}: line {number}: {kinds[slot]} {index}, but "
                                 f"{counts[key]} {names[slot]} so far")


_MTL_FILE_KEYS = (b"map_ka", b"map_kd", b"map_ks", b"map_ke", b"map_ns", b"map_d", b"map_bump", b"bump", b"disp",
                  b"decal", b"refl", b"norm", b"map_pr", b"map_pm", b"map_ps")


def _check_mtl_files(obj_path: Path, library: Path, roots) -> None:
    """The images a material library names (its last word on the line: options come first)."""
    for raw in library.read_bytes().splitlines():
        words = raw.split()
        if len(words) >= 2 and words[0].lower() in _MTL_FILE_KEYS:
            name = words[-1].decode("utf-8", "replace")
            _referenced(library, name, roots, "image", "material library")


def _check_mtl_numbers(library: Path) -> None:
    for number, raw in enumerate(library.read_bytes().splitlines(), 1):
        parts = raw.split()
        if parts and parts[0] in (b"Kd", b"Ka", b"Ks", b"Ke", b"Ns", b"d", b"Tr", b"Ni"):
            try:
                [float(v) for v in parts[1:]]
            except ValueError:
                text = raw.decode("utf-8", "replace")
                raise AssetError(f"material library {str(library)!r}: line {number}: "
                                 f"{parts[0].decode()} must be numbers, got {text!r}") from None


def _unit_color(value) -> np.ndarray:
    """A colour from trimesh (uint8 0..255 or float 0..1) as float RGBA."""
    c = np.asarray(value)
    c = c.astype(np.float64) / 255.0 if c.dtype.kind in "ui" else c.astype(np.float64)
    if len(c) == 3:
        c = np.append(c, 1.0)
    return c[:4]


def _mtl_texture_refs(obj_path: Path) -> dict[str, Path]:
    """``map_Kd`` files of the MTL libraries an OBJ names, by material name.

    trimesh drops a missing or undecodable texture silently (the model would render
    untextured); knowing what the MTL asked for lets the loader say so instead.
    """
    refs: dict[str, Path] = {}
    with open(obj_path, "rb") as f:
        libraries = [line[6:].strip().decode("utf-8", "replace") for line in f if line.startswith(b"mtllib")]
    for library in libraries:
        mtl_path = obj_path.parent / library
        if not mtl_path.is_file():
            continue
        material = None
        for line in mtl_path.read_text(encoding="utf-8", errors="replace").splitlines():
            words = line.split()
            if len(words) >= 2 and words[0] == "newmtl":
                material = " ".join(words[1:])
            elif len(words) >= 2 and words[0].lower() == "map_kd" and material is not None:
                refs[material] = mtl_path.parent / words[-1]
    return refs


def _read_material(tm, part: ModelPart, path: Path, texture_refs: dict[str, Path] | None = None) -> None:
    """Fill colour, texture, PBR factors and the emissive factor from trimesh's visual."""
    from trimesh.visual.material import SimpleMaterial

    visual = getattr(tm, "visual", None)
    material = getattr(visual, "material", None)
    if isinstance(material, SimpleMaterial) and not (material.kwargs or getattr(material, "_name", None)):
        # trimesh's placeholder for UVs without any material (a 2x2 grey image): the file has
        # no material, so the engine's defaults apply.
        material = None
    if material is None:
        if getattr(visual, "kind", None) in ("vertex", "face"):
            mean = np.asarray(visual.vertex_colors, np.float64).mean(axis=0) / 255.0
            part.color = tuple(float(_srgb_to_linear(c)) for c in mean[:3]) + (float(mean[3]),)
        return
    if hasattr(material, "baseColorFactor"):  # glTF PBR
        base = material.baseColorFactor
        if base is not None:
            part.color = tuple(float(c) for c in _unit_color(base))
        image = material.baseColorTexture
        # glTF's defaults are 1.0; trimesh reports an absent factor as None.  The engine
        # keeps its own defaults (dielectric, 0.5) for a file that says nothing.
        part.metallic = float(material.metallicFactor if material.metallicFactor is not None else 0.0)
        part.roughness = float(material.roughnessFactor if material.roughnessFactor is not None else 0.5)
        emissive = _floats(material.emissiveFactor)
        part.reflectivity = part.metallic
    else:  # OBJ/MTL SimpleMaterial
        extra = {str(k).lower(): v for k, v in (getattr(material, "kwargs", {}) or {}).items()}
        kd = _floats(extra.get("kd"))  # the file's exact floats (material.diffuse is quantized to uint8)
        color = _unit_color(material.diffuse)
        if kd is not None and len(kd) >= 3:
            color[:3] = kd[:3]
        if extra.get("d") is not None:
            color[3] = _first(extra.get("d"), 1.0)
        elif extra.get("tr") is not None:
            color[3] = 1.0 - _first(extra.get("tr"), 0.0)
        part.color = tuple(float(c) for c in color)
        image = material.image
        wanted = (texture_refs or {}).get(getattr(material, "_name", None) or "")
        if image is None and wanted is not None:
            why = "cannot be decoded as an image" if wanted.is_file() else "no such file"
            raise AssetError(f"texture {str(wanted)!r} of material {material.name!r}: {why}")
        emissive = _floats(extra.get("ke"))
        part.metallic = _first(extra.get("pm"), 0.0)
        part.roughness = _first(extra.get("pr"), 0.5)
        part.reflectivity = max(part.metallic, _first(extra.get("refl"), 0.0))
    if not all(np.isfinite(c) and 0.0 <= c <= 65504.0 for c in part.color) or part.color[3] > 1.0:
        raise AssetError(f"material diffuse colour {part.color} must be finite, in [0, 65504] (half floats), "
                         f"alpha <= 1")
    if emissive is not None and len(emissive) >= 1:
        if not all(np.isfinite(e) and 0.0 <= e <= 65504.0 for e in emissive[:3]):
            raise AssetError(f"material emissive colour {emissive[:3]} must be finite and >= 0")
        if max(emissive[:3]) > 0.0:
            # The file stores emissive as a multiple of diffuse; the factor is their
            # ratio (taken on the strongest channel, so a pure-blue lamp still works).
            channel = int(np.argmax(part.color[:3]))
            diffuse = max(part.color[channel], 1e-6)
            part.emissive_factor = float(np.clip(emissive[min(channel, len(emissive) - 1)] / diffuse, 0.0, 1e4))
    if image is not None:
        what = f"texture of {str(path)!r}"
        check_texture_size(*image.size, what)
        try:
            part.texture = TextureData(image_to_rgba8(image, what), name=f"{path.name}:texture")
        except (AssetError, MemoryError):
            raise
        except Exception as exc:
            raise AssetError(f"{what} cannot be decoded ({exc})") from exc
    for name in ("metallic", "roughness", "reflectivity"):
        value = getattr(part, name)
        if not (np.isfinite(value) and 0.0 <= value <= 1.0):
            raise AssetError(f"material {name} {value} is outside 0..1")


# --- material maps -----------------------------------------------------------------------

# MTL texture options and how many values each takes (-o, -s and -t take one to three); the
# file name is what follows them (it may hold spaces).
_MTL_OPTION_VALUES = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1, "-imfchan": 1,
                      "-texres": 1, "-type": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3}
_MTL_MAP_KEYS = ("norm", "map_bump", "bump", "map_ke")  # the maps an MTL gives beyond map_Kd


@dataclass(frozen=True)
class _MtlMap:
    """One map statement of a material library: the file, its ``-bm`` (None: not given), and
    where it was written (for errors)."""

    path: Path
    bump_scale: float | None
    library: Path
    line: int
    key: str


def _mtl_map_statement(words: list[str], library: Path, number: int, roots) -> _MtlMap:
    """``key [-option values...] file``: the options read (``-bm`` kept), the file checked
    (inside ``roots``, a regular file, there at all), every problem naming the library and line."""
    key = words[0].lower()
    where = f"material library {str(library)!r}: line {number}: {words[0]}"
    bump_scale, i = None, 1
    while i < len(words) and words[i].lower() in _MTL_OPTION_VALUES:
        option, count = words[i].lower(), _MTL_OPTION_VALUES[words[i].lower()]
        values = words[i + 1:i + 1 + count]
        if option in ("-o", "-s", "-t"):  # one to three numbers
            taken = 0
            for word in values:
                try:
                    float(word)
                except ValueError:
                    break
                taken += 1
            values = values[:taken]
        if option == "-bm":
            try:
                bump_scale = float(values[0]) if values else math.nan
            except ValueError:
                bump_scale = math.nan
            if not 0.0 <= bump_scale <= MAX_MTL_BUMP_SCALE:
                raise AssetError(f"{where}: -bm (the bump scale) must be a number in [0, {MAX_MTL_BUMP_SCALE:g}], "
                                 f"got {values[0] if values else 'nothing'!r}")
        i += 1 + len(values)
    name = " ".join(words[i:])
    if not name:
        raise AssetError(f"{where}: names no file")
    target = _referenced(library, name, roots, "image", "material library")
    if target is None:
        raise AssetError(f"{where}: its image {name!r} does not exist (looked for {str(library.parent / name)!r})")
    return _MtlMap(target, bump_scale, library, number, key)


MAX_MTL_BUMP_SCALE = 16.0  # Material.normal_scale's limit


def _mtl_maps(obj_path: Path, roots) -> dict[str, dict[str, _MtlMap]]:
    """The ``norm``, ``map_Bump`` / ``bump`` and ``map_Ke`` statements of the MTL libraries an
    OBJ names, by material name (trimesh reads none of them)."""
    maps: dict[str, dict[str, _MtlMap]] = {}
    with open(obj_path, "rb") as f:
        libraries = [line[6:].strip().decode("utf-8", "replace") for line in f if line.startswith(b"mtllib")]
    for library_name in libraries:
        library = obj_path.parent / library_name
        if not library.is_file():
            continue  # the OBJ check warned; the default material is used
        material = None
        for number, line in enumerate(library.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            words = line.split()
            if len(words) >= 2 and words[0] == "newmtl":
                material = " ".join(words[1:])
            elif words and words[0].lower() in _MTL_MAP_KEYS and material is not None:
                entry = _mtl_map_statement(words, library, number, roots)
                maps.setdefault(material, {})["bump" if entry.key == "map_bump" else entry.key] = entry
    return maps


class _MaterialMaps:
    """The material maps of a file's parts beyond the albedo texture: normal, emissive and
    metallic-roughness maps (glTF through trimesh's PBRMaterial, with the normal map's scale
    from the file's JSON, which trimesh drops; OBJ from the MTL statements, read here).  One
    image is one TextureData however many parts use it, so it is uploaded once."""

    def __init__(self, path: Path, gltf_doc: dict | None, roots) -> None:
        self.path = path
        materials = gltf_doc.get("materials") if isinstance(gltf_doc, dict) else None
        self.gltf_materials = [m for m in materials if isinstance(m, dict)] if isinstance(materials, list) else []
        self.mtl = _mtl_maps(path, roots) if path.suffix.lower() == ".obj" else {}
        self._made: dict[tuple, TextureData] = {}

    def read(self, tm: trimesh.Trimesh, part: ModelPart) -> None:
        from trimesh.visual.material import SimpleMaterial

        material = getattr(getattr(tm, "visual", None), "material", None)
        if material is None:
            return
        if hasattr(material, "baseColorFactor"):
            self._gltf(material, part)
        elif isinstance(material, SimpleMaterial):
            found = self.mtl.get(getattr(material, "_name", None) or "")
            if found:
                extra = {str(k).lower(): v for k, v in (getattr(material, "kwargs", {}) or {}).items()}
                self._obj(found, extra, part)

    # --- glTF ------------------------------------------------------------------------------
    def _gltf(self, material, part: ModelPart) -> None:
        what = f"material {material.name!r}"
        image = getattr(material, "normalTexture", None)
        if image is not None:
            part.normal_map = self._image(image, f"{what}: normalTexture", "normal")
            part.normal_scale = self._normal_scale(material.name, what)
        image = getattr(material, "metallicRoughnessTexture", None)
        if image is not None:
            # glTF: the factors multiply the texture (roughness G, metallic B); absent, they are 1.
            part.metallic_roughness_map = self._image(image, f"{what}: metallicRoughnessTexture", "linear")
            part.metallic = 1.0 if material.metallicFactor is None else float(material.metallicFactor)
            part.roughness = 1.0 if material.roughnessFactor is None else float(material.roughnessFactor)
            for name in ("metallic", "roughness"):
                value = getattr(part, name)
                if not (np.isfinite(value) and 0.0 <= value <= 1.0):
                    raise AssetError(f"{what}: {name}Factor {value} is outside 0..1")
            # Reflective where any texel is metal; the map's blue weighs the reflection per pixel.
            metal = part.metallic_roughness_map.pixels[..., 2].max() > 0
            part.reflectivity = part.metallic if metal else 0.0
        image = getattr(material, "emissiveTexture", None)
        factor = _floats(material.emissiveFactor)
        if image is not None and factor is not None and len(factor) >= 3 and max(factor[:3]) > 0.0:
            self._emissive(part, self._image(image, f"{what}: emissiveTexture", "colour"), factor[:3], what)

    def _image(self, image, what: str, kind: str) -> TextureData:
        """A decoded image of the file as a TextureData (once per image and kind)."""
        key = ("image", id(image), kind)
        texture = self._made.get(key)
        if texture is None:
            check_texture_size(*image.size, f"{what} of {str(self.path)!r}")
            try:
                pixels = image_to_rgba8(image, what)
            except (AssetError, MemoryError):
                raise
            except Exception as exc:
                raise AssetError(f"{what} of {str(self.path)!r} cannot be decoded ({exc})") from exc
            texture = self._made[key] = TextureData(pixels, name=f"{self.path.name}:{what.split(': ')[-1]}")
        return texture

    def _normal_scale(self, name, what: str) -> float:
        """The file's ``normalTexture.scale`` for the material called ``name`` (glTF default 1).
        trimesh keeps neither the scale nor the material's index, so materials are matched by
        name; a material no name picks gets the scale every normal texture of the file shares."""
        scales = [(m.get("name"), m["normalTexture"].get("scale", 1.0)) for m in self.gltf_materials
                  if isinstance(m.get("normalTexture"), dict)]
        named = [scale for n, scale in scales if n == name]
        shared = {repr(scale) for _, scale in scales}
        scale = named[0] if named else (scales[0][1] if len(shared) == 1 else 1.0)
        if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or \
                not 0.0 <= float(scale) <= MAX_MTL_BUMP_SCALE:
            raise AssetError(f"{what}: normalTexture.scale must be a number in [0, {MAX_MTL_BUMP_SCALE:g}], "
                             f"got {scale!r}")
        return float(scale)

    def _emissive(self, part: ModelPart, texture: TextureData, factor: list[float], what: str) -> None:
        """An emissive map emitted at the factor's largest channel (``Emissive.power``); a
        factor that is not grey has its hue (factor / largest) multiplied into the texels, in
        linear light, so the emitted colour is the file's factor x texture."""
        if not all(np.isfinite(e) and 0.0 <= e <= 65504.0 for e in factor):
            raise AssetError(f"{what}: emissive colour {factor} must be finite and >= 0")
        strength = max(factor)
        hue = np.asarray(factor, np.float64) / strength
        if not np.all(hue == 1.0):
            key = ("tinted", id(texture), tuple(hue))
            tinted = self._made.get(key)
            if tinted is None:
                linear = _srgb_to_linear_array(texture.as_8_bits()[..., :3] / 255.0) * hue
                pixels = texture.as_8_bits().copy()
                pixels[..., :3] = np.rint(_linear_to_srgb_array(linear) * 255.0).astype(np.uint8)
                tinted = self._made[key] = TextureData(pixels, name=f"{texture.name} x {list(hue)}")
            texture = tinted
        part.emissive_map = texture
        part.emissive_factor = float(min(strength, 1e4))

    # --- OBJ / MTL -------------------------------------------------------------------------
    def _obj(self, found: dict[str, _MtlMap], extra: dict, part: ModelPart) -> None:
        entry = found.get("norm") or found.get("bump")
        if entry is not None:
            texture = self._file(entry.path, True)
            if entry.key != "norm" and is_grey(texture):  # a height map: its slopes become normals
                key = ("heights", entry.path)
                if key not in self._made:
                    self._made[key] = height_to_normal_map(texture)
                texture = self._made[key]
            part.normal_map = texture
            part.normal_scale = 1.0 if entry.bump_scale is None else entry.bump_scale
        entry = found.get("map_ke")
        if entry is not None:
            ke = _floats(extra.get("ke"))
            factor = [1.0, 1.0, 1.0] if ke is None else (ke * 3 if len(ke) == 1 else ke[:3])
            if max(factor) > 0.0:
                self._emissive(part, self._file(entry.path, False), factor,
                               f"material library {str(entry.library)!r}: line {entry.line}")

    def _file(self, path: Path, linear: bool) -> TextureData:
        key = ("file", str(path), linear)
        texture = self._made.get(key)
        if texture is None:
            texture = self._made[key] = load_texture(path, keep_16_bits=linear)
        return texture


def _srgb_to_linear_array(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb_array(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1.0 / 2.4) - 0.055)


def _floats(value) -> list[float] | None:
    if value is None:
        return None
    try:
        return [float(v) for v in (value if isinstance(value, (list, tuple, np.ndarray)) else [value])]
    except (TypeError, ValueError):
        return None


def _first(value, default: float) -> float:
    numbers = _floats(value)
    return numbers[0] if numbers else default


def _srgb_to_linear(c: float) -> float:
    c = float(c)
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


UV_FIT_TOLERANCE = 1e-3  # of the UVs' range: how far from an affine map of position they may be


def planar_uv_map(mesh: Mesh) -> tuple[np.ndarray | None, str]:
    """The mesh's UVs as an affine function of model position, (2, 4) rows (u and v as
    ``dot(row.xyz, p) + row.w``), fitted to its vertices by least squares (on a flat mesh
    the part along the normal is the smallest); (None, why) when they are not one (a
    bumpy mirror's composite works its UVs out from the plane point it shades)."""
    points = np.hstack([mesh.positions.astype(np.float64), np.ones((len(mesh.positions), 1))])
    uvs = mesh.uvs.astype(np.float64)
    rows, *_ = np.linalg.lstsq(points, uvs, rcond=None)  # (4, 2)
    span = float(np.ptp(uvs, axis=0).max())
    if not span > 0.0:
        return None, "its UVs do not vary"
    error = float(np.abs(points @ rows - uvs).max())
    if not error <= UV_FIT_TOLERANCE * span:
        return None, f"its UVs are off a plane map by {error:.3g}"
    return rows.T, ""
