"""Mesh data on the CPU, the built-in primitives, and loading mesh files through trimesh.

A Mesh is plain arrays; the renderer uploads it once and shares it between every entity
whose MeshRef points at it.
"""
from __future__ import annotations

import itertools
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pyglm import glm

from engine.errors import AssetError
from engine.texture_data import TextureData

_mesh_ids = itertools.count(1)


@dataclass(eq=False)
class Mesh:
    """Indexed triangles: positions, normals (unit), uvs, and int32 triangle indices."""

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
    def from_trimesh(cls, tm, name: str = "mesh") -> Mesh:
        """Convert a trimesh.Trimesh (its UVs are used when it has them)."""
        uv = getattr(getattr(tm, "visual", None), "uv", None)
        positions = np.asarray(tm.vertices, np.float32)
        if len(positions) == 0 or len(tm.faces) == 0:
            raise AssetError(f"mesh {name!r}: has no triangles")
        if uv is None or len(uv) != len(positions):
            uv = np.zeros((len(positions), 2), np.float32)
        if not np.isfinite(positions).all():
            raise AssetError(f"mesh {name!r}: has NaN or infinite vertex data")
        return cls(positions, _unit_normals(tm), uv, np.asarray(tm.faces), name=name)


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

def box(size: tuple[float, float, float] = (1.0, 1.0, 1.0), name: str = "box") -> Mesh:
    """An axis-aligned box centred on the origin, flat normals, 0..1 UVs per face."""
    hx, hy, hz = (s * 0.5 for s in size)
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
    """A flat rectangle in the XZ plane facing +Y."""
    hw, hd = width / 2, depth / 2
    positions = np.array([(-hw, 0, hd), (hw, 0, hd), (hw, 0, -hd), (-hw, 0, -hd)])
    normals = np.tile((0.0, 1.0, 0.0), (4, 1))
    uvs = np.array([(0, 0), (1, 0), (1, 1), (0, 1)]) * uv_repeat
    source = {"plane": [float(width), float(depth)], **({} if uv_repeat == 1.0 else {"uv_repeat": float(uv_repeat)}),
              **({} if name == "plane" else {"name": name})}
    return Mesh(positions, normals, uvs, np.array([(0, 1, 2), (0, 2, 3)]), name=name, source=source)


def quad(width: float = 1.0, height: float = 1.0, name: str = "quad") -> Mesh:
    """A flat rectangle in the XY plane facing +Z (mirrors and portals use it)."""
    hw, hh = width / 2, height / 2
    positions = np.array([(-hw, -hh, 0), (hw, -hh, 0), (hw, hh, 0), (-hw, hh, 0)])
    normals = np.tile((0.0, 0.0, 1.0), (4, 1))
    uvs = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
    return Mesh(positions, normals, uvs, np.array([(0, 1, 2), (0, 2, 3)]), name=name,
                source={"quad": [float(width), float(height)], **({} if name == "quad" else {"name": name})})


MAX_SPHERE_DIVISIONS = 1024  # segments or rings of a generated sphere (a million triangles at most)


def sphere(radius: float = 0.5, segments: int = 48, rings: int = 24, name: str = "sphere") -> Mesh:
    """A UV sphere with smooth normals."""
    for what, value, low in (("segments", segments, 3), ("rings", rings, 2)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= MAX_SPHERE_DIVISIONS:
            raise AssetError(f"sphere mesh {name!r}: {what} must be an int in [{low}, {MAX_SPHERE_DIVISIONS}], "
                             f"got {value!r}")
    theta = np.linspace(0.0, np.pi, rings + 1)          # from +Y down
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    uvs = np.stack([p / (2 * np.pi), 1.0 - t / np.pi], axis=-1).reshape(-1, 2)
    row = segments + 1
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = (i * row + j).ravel()
    b, c, d = a + row, a + row + 1, a + 1
    indices = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    source = {"sphere": float(radius), **({} if segments == 48 else {"segments": int(segments)}),
              **({} if rings == 24 else {"rings": int(rings)}), **({} if name == "sphere" else {"name": name})}
    return Mesh(normals * radius, normals, uvs, indices, name=name, source=source)


# --- loading files -----------------------------------------------------------------------

@dataclass
class ModelPart:
    """One mesh of a loaded file with the material the file gave it."""

    mesh: Mesh
    local: glm.mat4
    color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: TextureData | None = None
    metallic: float = 0.0
    roughness: float = 0.5
    emissive_factor: float = 0.0   # emissive colour / diffuse colour
    reflectivity: float = 0.0


SUPPORTED_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")


def load_model(path: str | Path) -> list[ModelPart]:
    """Load every mesh of a file with trimesh; errors name the file and the reason."""
    import trimesh

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"mesh file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"mesh file {str(path)!r}: no such file")
    if path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise AssetError(f"mesh file {str(path)!r}: unsupported type {path.suffix!r} "
                         f"(supported: {', '.join(SUPPORTED_SUFFIXES)})")
    if path.stat().st_size == 0:
        raise AssetError(f"mesh file {str(path)!r}: file is empty")
    if path.suffix.lower() == ".gltf":
        _check_gltf_json(path)
    elif path.suffix.lower() == ".obj":
        _check_obj_text(path)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds for corrupt files
        raise AssetError(f"mesh file {str(path)!r}: cannot be parsed ({type(exc).__name__}: {exc})") from exc
    parts: list[ModelPart] = []
    try:
        texture_refs = _mtl_texture_refs(path) if path.suffix.lower() == ".obj" else {}
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
            parts.append(part)
    except AssetError as exc:
        raise AssetError(f"mesh file {str(path)!r}: {exc}") from exc
    except Exception as exc:  # trimesh computing normals/visuals of malformed data
        raise AssetError(f"mesh file {str(path)!r}: holds malformed mesh data "
                         f"({type(exc).__name__}: {exc})") from exc
    if not parts:
        raise AssetError(f"mesh file {str(path)!r}: contains no triangle meshes")
    return parts


def _check_gltf_json(path: Path) -> None:
    """A .gltf is JSON; say so plainly instead of trimesh's guess at a missing buffer file."""
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise AssetError(f"mesh file {str(path)!r}: is not a JSON glTF file ({type(exc).__name__})") from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise AssetError(f"mesh file {str(path)!r}: is not a glTF document (no 'asset' object)")


def _check_obj_text(path: Path) -> None:
    """What trimesh accepts silently in an OBJ: a face index 0, a missing MTL, a non-numeric Kd."""
    with path.open("rb") as f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            if line.startswith(b"f ") and any(tok.split(b"/")[0] in (b"0", b"-0") for tok in line.split()[1:]):
                raise AssetError(f"mesh file {str(path)!r}: line {number}: face index 0 (OBJ indices start at 1)")
            if line.startswith(b"mtllib"):
                for name in line[6:].decode("utf-8", "replace").split():
                    library = path.parent / name
                    if not library.is_file():
                        warnings.warn(f"mesh file {str(path)!r}: material library {name!r} not found; "
                                      f"default material used", stacklevel=3)
                        continue
                    _check_mtl_numbers(library)


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
        try:
            part.texture = TextureData(np.asarray(image.convert("RGBA")), name=f"{path.name}:texture")
        except Exception as exc:
            raise AssetError(f"texture of {str(path)!r} cannot be decoded ({exc})") from exc
    for name in ("metallic", "roughness", "reflectivity"):
        value = getattr(part, name)
        if not (np.isfinite(value) and 0.0 <= value <= 1.0):
            raise AssetError(f"material {name} {value} is outside 0..1")


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
