"""Mesh data on the CPU, the built-in primitives, and loading mesh files through trimesh.

A Mesh is plain arrays; the renderer uploads it once and shares it between every entity
whose MeshRef points at it.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import itertools
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

from components.limits import MAX_DISPERSION, MAX_FILM_THICKNESS, MAX_IOR, MAX_MORPH_TARGETS
from components.water import f0_from_ior
from engine.assets.gltf_animations import collapsed, moved_nodes
from engine.assets.gltf_morphs import morph_arrays
from engine.assets.gltf_skins import skin_arrays
from engine.assets.gltf_uv_sets import UvPlan, UvSource, moved_uvs, uv_sets
from engine.assets.gltf_variants import variant_names
from engine.assets.model_cameras import ModelCamera, read_gltf_cameras
from engine.assets.model_files import (
    MAX_JSON_NESTING,  # noqa: F401 - the loader's limits are read from here too
    MAX_MTL_BUMP_SCALE,
    CheckedFiles,
    GltfFiles,
    MtlMap,
    ObjFiles,
    prepare_gltf,
    prepare_obj,
)
from engine.assets.model_lights import ModelLight, read_gltf_lights
from engine.assets.texture_data import (
    MAX_TEXTURE_SIDE,
    WORK_BLOCK,
    TextureData,
    check_asset_file,
    check_texture_size,
    height_to_normal_map,
    image_to_rgba8,
    is_grey,
    load_texture,
    pillow_image_module,
    read_asset_file,
)
from engine.core.color import linear_to_srgb, srgb_to_linear
from engine.core.errors import AssetError
from engine.core.skinning import INFLUENCES, MAX_JOINTS, joint_boxes, strongest_influences

if TYPE_CHECKING:  # trimesh is imported when a mesh file is first loaded
    import trimesh

_mesh_ids = itertools.count(1)


@dataclass(eq=False)
class Mesh:
    """Indexed triangles: positions, normals (unit), uvs, and int32 triangle indices; and
    optionally a colour a vertex (``colors``: linear RGB, or RGBA with an alpha in [0, 1],
    interpolated across each triangle and multiplied into the material's colour, as glTF's
    ``COLOR_0``; None: none).  A vertex's alpha, like a texture's, is drawn where the material
    is see-through (its colour's alpha below 1: blended) or a cutout (cut at its
    ``alpha_cutoff``, in every view and shadow map); an opaque material ignores it."""

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
    # A generated box, quad or sphere is its shape's unit mesh scaled (``unit``, made when first
    # asked for): the renderer draws every size of a shape as instances of that one mesh, each
    # row's model matrix carrying its size, so boxes of ten sizes are one draw a pass, not ten.
    unit_shape: tuple | None = field(default=None, repr=False)  # (kind, segments, rings)
    unit_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    colors: np.ndarray | None = field(default=None, repr=False)
    # A skinned mesh's joints and weights a vertex (glTF's JOINTS_0 and WEIGHTS_0): up to
    # four joints of its Skin each vertex follows (uint16, (V, 4)) and how much (float32,
    # summing to 1); None: not skinned (engine/core/skinning.py).
    joints: np.ndarray | None = field(default=None, repr=False)
    weights: np.ndarray | None = field(default=None, repr=False)
    # Morph targets (glTF's ``targets``: blend shapes): each target's offset a vertex of its
    # positions and of its normals (float32, (T, V, 3); normals None: not moved), added by a
    # ``Morph``'s weights (engine/core/skinning.py); None: none.
    morph_positions: np.ndarray | None = field(default=None, repr=False)
    morph_normals: np.ndarray | None = field(default=None, repr=False)
    # A second set of UVs (glTF's TEXCOORD_1, or a map's own transform of the first: a
    # lightmap's or a baked occlusion map's unwrapping), float32 (V, 2); None: none.  The maps
    # a Material's ``second_uv_maps`` names read it, the others ``uvs``.
    second_uvs: np.ndarray | None = field(default=None, repr=False)

    @property
    def unit(self) -> Mesh | None:
        """The unit mesh this one is, scaled by ``unit_scale`` (None: drawn as it is)."""
        return None if self.unit_shape is None else _unit_mesh(*self.unit_shape)

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
        if self.colors is not None:
            colors = np.asarray(self.colors)
            if colors.ndim != 2 or colors.shape[0] != n or colors.shape[1] not in (3, 4) or \
                    not np.issubdtype(colors.dtype, np.number):
                raise AssetError(f"mesh {self.name!r}: colors must be one linear RGB or RGBA colour a vertex, shape "
                                 f"({n}, 3) or ({n}, 4), got shape {colors.shape}")
            colors = np.ascontiguousarray(colors, np.float32)
            if not (np.isfinite(colors).all() and colors.min() >= 0.0 and colors.max() <= 65504.0):
                raise AssetError(f"mesh {self.name!r}: colors must be finite, in [0, 65504] (half floats)")
            if colors.shape[1] == 4 and colors[:, 3].max() > 1.0:
                raise AssetError(f"mesh {self.name!r}: a colour's alpha must be in [0, 1], got up to "
                                 f"{float(colors[:, 3].max()):g}")
            self.colors = colors
        if self.joints is not None or self.weights is not None:
            self._check_skin(n)
        if self.morph_positions is not None or self.morph_normals is not None:
            self._check_morphs(n)
        if self.second_uvs is not None:
            second = np.asarray(self.second_uvs)
            if second.ndim != 2 or second.shape != (n, 2) or not np.issubdtype(second.dtype, np.number):
                raise AssetError(f"mesh {self.name!r}: second_uvs must be one UV pair a vertex, shape ({n}, 2), "
                                 f"got shape {second.shape}")
            second = np.ascontiguousarray(second, np.float32)
            if not np.isfinite(second).all():
                raise AssetError(f"mesh {self.name!r}: second_uvs has NaN or infinite values")
            self.second_uvs = second

    def _check_morphs(self, n: int) -> None:
        """Each target's offsets a vertex: positions, and normals or none."""
        if self.morph_positions is None:
            raise AssetError(f"mesh {self.name!r}: morph_normals without morph_positions (a target moves its "
                             "positions; give zeros where it moves only normals)")
        for name in ("morph_positions", "morph_normals"):
            offsets = getattr(self, name)
            if offsets is None:
                continue
            offsets = np.asarray(offsets)
            if offsets.ndim != 3 or offsets.shape[1:] != (n, 3) or not 1 <= len(offsets) <= MAX_MORPH_TARGETS \
                    or not np.issubdtype(offsets.dtype, np.number):
                raise AssetError(f"mesh {self.name!r}: {name} must be 1 to {MAX_MORPH_TARGETS} targets "
                                 f"(MAX_MORPH_TARGETS) of one offset a vertex, shape (T, {n}, 3); got {offsets.shape}")
            offsets = np.ascontiguousarray(offsets, np.float32)
            if not np.isfinite(offsets).all():
                raise AssetError(f"mesh {self.name!r}: {name} has NaN or infinite offsets")
            setattr(self, name, offsets)
        if self.morph_normals is not None and len(self.morph_normals) != len(self.morph_positions):
            raise AssetError(f"mesh {self.name!r}: {len(self.morph_positions)} position targets but "
                             f"{len(self.morph_normals)} normal targets")

    @property
    def morph_count(self) -> int:
        """How many morph targets it has (a ``Morph`` on it gives as many weights; 0: none)."""
        return len(self.morph_positions) if self.morph_positions is not None else 0

    def morph_offset_boxes(self) -> np.ndarray:
        """Each target's box of position offsets (T, 2, 3): how far it can move a vertex."""
        boxes = self.__dict__.get("_morph_offset_boxes")
        if boxes is None:
            offsets = self.morph_positions.astype(np.float64)
            boxes = self.__dict__["_morph_offset_boxes"] = np.stack([offsets.min(axis=1), offsets.max(axis=1)], axis=1)
        return boxes

    def morph_texels(self) -> np.ndarray:
        """The morph texture's texels (V x T x 2, 4 floats): for each vertex, each target's
        position offset then its normal offset (``shaders/include/pose.glsl``)."""
        count, vertices = self.morph_count, len(self.positions)
        texels = np.zeros((vertices, count, 2, 4), np.float32)
        texels[:, :, 0, :3] = self.morph_positions.transpose(1, 0, 2)
        if self.morph_normals is not None:
            texels[:, :, 1, :3] = self.morph_normals.transpose(1, 0, 2)
        return texels.reshape(-1, 4)

    def _check_skin(self, n: int) -> None:
        """Joints and weights a vertex, both or neither: a vertex's strongest four kept
        (``skinning.strongest_influences``), its weights made to sum to 1."""
        if self.joints is None or self.weights is None:
            raise AssetError(f"mesh {self.name!r}: a skinned mesh needs both joints and weights a vertex, got "
                             f"{'joints' if self.weights is None else 'weights'} alone")
        joints, weights = np.asarray(self.joints), np.asarray(self.weights)
        if joints.ndim != 2 or joints.shape[0] != n or not 1 <= joints.shape[1] <= 4 * INFLUENCES \
                or weights.shape != joints.shape:
            raise AssetError(f"mesh {self.name!r}: joints and weights must be one row a vertex of the same width (1 "
                             f"to {4 * INFLUENCES}), shape ({n}, k); got {joints.shape} and {weights.shape}")
        if not np.issubdtype(joints.dtype, np.integer) or (len(joints) and (joints.min() < 0
                                                                            or joints.max() >= MAX_JOINTS)):
            raise AssetError(f"mesh {self.name!r}: joints must be integers in 0..{MAX_JOINTS - 1} (MAX_JOINTS: a "
                             f"skin's joints), got {joints.dtype} from {joints.min()} to {joints.max()}")
        if not np.issubdtype(weights.dtype, np.number) or not np.isfinite(weights).all() or weights.min() < 0.0:
            raise AssetError(f"mesh {self.name!r}: weights must be finite numbers >= 0")
        joints, weights = strongest_influences(joints, weights)
        unmoved = int((weights.sum(axis=1) == 0.0).sum())
        if unmoved:
            raise AssetError(f"mesh {self.name!r}: {unmoved} vertices have weights summing to 0 (glTF: a vertex's "
                             "weights sum to 1; it would follow no joint)")
        self.joints = np.ascontiguousarray(joints, np.uint16)
        self.weights = np.ascontiguousarray(weights, np.float32)

    @property
    def skinned(self) -> bool:
        """Whether it has joints and weights a vertex (a ``Skin`` bends it)."""
        return self.joints is not None

    @property
    def joint_count(self) -> int:
        """How many joint matrices a ``Skin`` bending it needs (its highest joint + 1; 0: not skinned)."""
        return int(self.joints.max()) + 1 if self.joints is not None else 0

    def joint_boxes(self) -> np.ndarray:
        """Each joint's box of the vertices it moves (``skinning.joint_boxes``), made once."""
        boxes = self.__dict__.get("_joint_boxes")
        if boxes is None:
            boxes = self.__dict__["_joint_boxes"] = joint_boxes(self.positions, self.joints, self.weights,
                                                                self.joint_count)
        return boxes

    def skin_interleaved(self) -> bytes:
        """The skin buffer: a vertex's four joints (uint16) and weights (float32), 24 bytes."""
        rows = np.zeros(len(self.joints), [("joints", "<u2", (4,)), ("weights", "<f4", (4,))])
        rows["joints"], rows["weights"] = self.joints, self.weights
        return rows.tobytes()

    @property
    def has_alpha(self) -> bool:
        """Whether some vertex's colour has an alpha below 1."""
        return self.colors is not None and self.colors.shape[1] == 4 and bool((self.colors[:, 3] < 1.0).any())

    def rgba_colors(self) -> np.ndarray | None:
        """The colours a vertex as RGBA (alpha 1 where they are RGB), what the GPU reads."""
        if self.colors is None or self.colors.shape[1] == 4:
            return self.colors
        return np.ascontiguousarray(np.hstack([self.colors, np.ones((len(self.colors), 1), np.float32)]))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Model-space AABB (min, max)."""
        return self.positions.min(axis=0), self.positions.max(axis=0)

    def interleaved(self) -> np.ndarray:
        """Vertex buffer contents: position, normal, uv per vertex (8 floats), and the second
        uv where it has one (10: the scene shaders' ``in_uv`` is a vec4, its zw the second set)."""
        sets = [self.uvs] if self.second_uvs is None else [self.uvs, self.second_uvs]
        return np.hstack([self.positions, self.normals, *sets]).astype(np.float32)

    @property
    def vertex_format(self) -> str:
        """The vertex buffer's layout as moderngl reads it (``interleaved``)."""
        return "3f 3f 2f" if self.second_uvs is None else "3f 3f 4f"

    @classmethod
    def from_trimesh(cls, tm: trimesh.Trimesh, name: str = "mesh", srgb_colors: bool = True) -> Mesh:
        """Convert a trimesh.Trimesh (its UVs are used when it has them, and its vertex or
        face colours: ``srgb_colors`` says they are sRGB-encoded, as PLY, OFF and OBJ files
        keep them; glTF's are linear).  Face colours make each triangle's corners vertices of
        their own, so the colour does not bleed across edges."""
        if getattr(getattr(tm, "visual", None), "kind", None) == "face":
            return _face_coloured(tm, name, srgb_colors)
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
        return cls(positions, _unit_normals(tm), uv, faces, name=name,
                   colors=_vertex_colors(tm, len(positions), srgb_colors, name))


def _vertex_colors(tm, count: int, srgb: bool, name: str) -> np.ndarray | None:
    """A trimesh's colour a vertex as linear RGB, or RGBA where some alpha is below 1 (None:
    none, or all opaque white): a vertex-coloured visual's, or a textured one's ``color``
    attribute (glTF's COLOR_0 beside a material).  The alpha is linear in every format."""
    visual = getattr(tm, "visual", None)
    colors = None
    if getattr(visual, "kind", None) == "vertex":
        colors = np.asarray(visual.vertex_colors)
    else:
        attributes = getattr(visual, "vertex_attributes", None)
        if attributes is not None and "color" in attributes:
            colors = np.asarray(attributes["color"])
    if colors is None:
        return None
    if colors.ndim != 2 or len(colors) != count or colors.shape[1] not in (3, 4):
        raise AssetError(f"mesh {name!r}: vertex colours of shape {colors.shape} for {count} vertices")
    values = colors.astype(np.float64)
    if colors.dtype.kind in "ui":
        values /= float(np.iinfo(colors.dtype).max)
    if not np.isfinite(values).all():
        raise AssetError(f"mesh {name!r}: has NaN or infinite vertex colours")
    values = np.clip(values, 0.0, 1.0)
    rgb = values[:, :3]
    alpha = values[:, 3:] if values.shape[1] == 4 and (values[:, 3] < 1.0).any() else None
    if (rgb == 1.0).all() and alpha is None:
        return None
    rgb = srgb_to_linear(rgb) if srgb else rgb
    return (rgb if alpha is None else np.hstack([rgb, alpha])).astype(np.float32)


def _face_coloured(tm, name: str, srgb: bool) -> Mesh:
    """A face-coloured trimesh as a mesh whose triangles have corners of their own, each
    corner its face's colour and normal."""
    faces = np.asarray(tm.faces)
    positions = np.asarray(tm.vertices, np.float32)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0 or not np.issubdtype(faces.dtype, np.integer):
        raise AssetError(f"mesh {name!r}: faces are not triangles of vertex indices (shape {faces.shape})")
    if faces.min() < 0 or faces.max() >= len(positions):
        raise AssetError(f"mesh {name!r}: face index out of range ({len(positions)} vertices)")
    corners = positions[faces].reshape(-1, 3)
    normals = np.repeat(np.asarray(tm.face_normals, np.float32), 3, axis=0)
    colors = np.asarray(tm.visual.face_colors)
    rgb = np.clip(colors[:, :3].astype(np.float64) / (255.0 if colors.dtype.kind in "ui" else 1.0), 0.0, 1.0)
    rgb = np.repeat(srgb_to_linear(rgb) if srgb else rgb, 3, axis=0).astype(np.float32)
    return Mesh(corners, normals, np.zeros((len(corners), 2), np.float32),
                np.arange(len(corners), dtype=np.int32).reshape(-1, 3), name=name, colors=rgb)


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
# Sizes a generated mesh is drawn as its unit mesh scaled: each side in this range (a side of 0,
# a flat box, would make the model matrix singular and its normal matrix infinite).
UNIT_SCALES = (1e-3, 1e6)


@functools.lru_cache(maxsize=32)
def _unit_mesh(kind: str, segments: int = 0, rings: int = 0) -> Mesh:
    """The one unit mesh of a shape (a 1 m box or quad, a sphere of radius 1 with these
    divisions), shared by every generated mesh of that shape the renderer draws."""
    unit = box(name="unit box") if kind == "box" else quad(name="unit quad") if kind == "quad" else \
        sphere(1.0, segments, rings, name="unit sphere")
    unit.unit_shape = None  # drawn as itself
    return unit


def _scaled_unit(mesh: Mesh, kind: str, scale: tuple[float, float, float], segments: int = 0, rings: int = 0) -> Mesh:
    """``mesh`` marked as its shape's unit mesh scaled by ``scale`` (``Mesh.unit``), where every
    side is in ``UNIT_SCALES``; other sizes are drawn as they are."""
    low, high = UNIT_SCALES
    if not all(low <= side <= high for side in scale):
        return mesh
    mesh.unit_shape = (kind, segments, rings)
    mesh.unit_scale = tuple(float(side) for side in scale)
    return mesh


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
    made = Mesh(np.array(positions), np.array(normals), np.array(uvs), np.array(indices), name=name,
                source={"box": [float(s) for s in size], **({} if name == "box" else {"name": name})})
    return _scaled_unit(made, "box", (2.0 * hx, 2.0 * hy, 2.0 * hz))


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
    made = Mesh(positions, normals, uvs, np.array([(0, 1, 2), (0, 2, 3)]), name=name,
                source={"quad": [float(width), float(height)], **({} if name == "quad" else {"name": name})})
    return _scaled_unit(made, "quad", (width, height, 1.0))


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
    made = Mesh(positions.reshape(count, 3), normals.reshape(count, 3), uvs.reshape(count, 2), indices.reshape(-1, 3),
                name=name, source=source)
    return _scaled_unit(made, "sphere", (radius, radius, radius), segments, rings)


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
    not the ratio of emissive to diffuse colour it is without one.  An MTL's ``map_d`` (its
    dissolve map) is multiplied into the texture's alpha, making an opaque material a
    cutout (``alpha_cutoff``; glTF's ``alphaMode`` MASK gives one too)."""

    mesh: Mesh
    local: glm.mat4
    color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: TextureData | None = None
    metallic: float = 0.0
    roughness: float = 0.5
    emissive_factor: float = 0.0   # emissive colour / diffuse colour (with an emissive map: its strength)
    emissive_rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)  # glTF's emissiveFactor (what a pointer animates)
    emissive_strength: float = 1.0  # glTF's KHR_materials_emissive_strength (likewise)
    reflectivity: float = 0.0
    normal_map: TextureData | None = None
    normal_scale: float = 1.0
    emissive_map: TextureData | None = None
    metallic_roughness_map: TextureData | None = None
    occlusion_map: TextureData | None = None   # glTF's occlusionTexture (Material.occlusion_map)
    occlusion_strength: float = 1.0            # its strength
    double_sided: bool = False         # glTF's doubleSided (Material.double_sided)
    alpha_cutoff: float | None = None  # glTF's alphaMode MASK: its alphaCutoff (Material.alpha_cutoff)
    transmission: float = 0.0  # KHR_materials_transmission's factor: the light that passes through (glass)
    ior: float = 1.5           # KHR_materials_ior's index of refraction (Refractive.ior)
    thick: bool = False        # KHR_materials_volume's thickness > 0: a solid, not a thin wall (Refractive.solid)
    dispersion: float = 0.0    # KHR_materials_dispersion's (Refractive.dispersion)
    clearcoat: float = 0.0            # KHR_materials_clearcoat's factor (Material.clearcoat)
    clearcoat_roughness: float = 0.0  # its roughness factor (Material.clearcoat_roughness)
    unlit: bool = False               # KHR_materials_unlit (Material.unlit)
    reflectance: float = 0.5          # from KHR_materials_ior and _specular (Material.reflectance)
    specular_color: tuple[float, float, float] = (1.0, 1.0, 1.0)  # its tint (Material.specular_color)
    diffuse_transmission: float = 0.0  # KHR_materials_diffuse_transmission's factor (Material.diffuse_transmission)
    diffuse_transmission_color: tuple[float, float, float] = (1.0, 1.0, 1.0)  # its colour factor
    sheen_color: tuple[float, float, float] = (0.0, 0.0, 0.0)  # KHR_materials_sheen's (Material.sheen_color)
    sheen_roughness: float = 0.0      # its roughness factor (Material.sheen_roughness)
    anisotropy: float = 0.0           # KHR_materials_anisotropy's strength (Material.anisotropy)
    anisotropy_direction: float = 0.0  # its rotation, in degrees (Material.anisotropy_direction)
    iridescence: float = 0.0          # KHR_materials_iridescence's factor (Material.iridescence)
    iridescence_ior: float = 1.3      # its film's index (Material.iridescence_ior)
    iridescence_thickness: float = 400.0  # its film's thickness in nm (Material.iridescence_thickness)
    name: str = ""  # "file:part", as a level file's part = "..." names it (parts may share one mesh)
    node: int | None = None  # its glTF node's index (what an animation moves; None: not a glTF's)
    skin: int | None = None  # its glTF node's skin (LoadedModel.skins: what bends it; None: not skinned)
    morph_weights: tuple[float, ...] | None = None  # the weights its node wears its morph targets at (None: none)
    hidden: bool = False     # its node is scaled to nothing at rest (a clip grows it): spawned not visible
    second_uv_maps: tuple[str, ...] = ()  # the maps that read its mesh's second UV set (Material.second_uv_maps)
    material: int | None = None  # its glTF material's index (what an animation pointer names; None: none)

    def __post_init__(self) -> None:
        if not self.name:
            self.name = self.mesh.name


SUPPORTED_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")
MAX_MESH_FILE_BYTES = 256 << 20  # a mesh file's size: trimesh holds several times it while parsing


@dataclass
class LoadedModel:
    """A model file's parts, the lights its nodes carry (a glTF's ``KHR_lights_punctual``,
    ``engine/assets/model_lights.py``) and its cameras (``engine/assets/model_cameras.py``);
    other formats have neither."""

    parts: list[ModelPart]
    lights: list[ModelLight]
    cameras: list[ModelCamera] = field(default_factory=list)
    variants: list[str] = field(default_factory=list)  # its material variants' names (KHR_materials_variants)
    animations: list = field(default_factory=list)     # its clips (engine/assets/gltf_animations.py Clip)
    node_tree: object = None                           # its nodes (gltf_animations.NodeTree), with clips or skins
    skins: list = field(default_factory=list)          # its skins (engine/assets/gltf_skins.py SkinDef)
    side_files: list[Path] = field(default_factory=list)  # the files beside it that it names and were found


def load_model(path: str | Path, roots: Sequence[str | Path] | None = None,
               materials: bool = True) -> list[ModelPart]:
    """The parts of ``load_model_file``: every mesh of a file, with its material."""
    return load_model_file(path, roots, materials).parts


def load_model_file(path: str | Path, roots: Sequence[str | Path] | None = None,
                    materials: bool = True, variant: str | None = None) -> LoadedModel:
    """Load every mesh of a file with trimesh, and the lights it carries; errors name the
    file and the reason.

    The file, and every file it names (an OBJ's material libraries and their maps, a glTF's
    buffers and images), is resolved and read by the engine (engine/assets/model_files.py):
    inside ``roots`` (folders; None: the model's own folder), a regular file (a FIFO, a
    device or a directory is refused before anything opens it), within its size limit
    before it is read; trimesh is handed those bytes and opens nothing itself. A file past
    MAX_MESH_FILE_BYTES, JSON nested past MAX_JSON_NESTING, an image past the texture
    limits (checked from its header before it is decoded), a glTF or MTL map that is missing
    or not an image (named with its material), or running out of memory is an AssetError.

    ``materials`` False: the meshes alone (what a level file takes from a model, its
    MeshRef): the images the materials name are checked by name but neither read nor
    decoded, and the parts keep the default material. Parts with the same geometry (glTF
    nodes sharing a mesh, or identical arrays) share one Mesh, so it is uploaded once and
    drawn instanced.  ``variant``: a glTF's material variant (``KHR_materials_variants``,
    engine/assets/gltf_variants.py) its parts wear; None or "": its default look; a variant
    it does not have is an AssetError listing those it has."""
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
    if roots is None:
        roots = [path.parent]
    elif isinstance(roots, (str, bytes, os.PathLike)) or not all(isinstance(r, (str, os.PathLike)) for r in roots):
        raise AssetError(f"{what}: roots must be a list of folders, got {roots!r}")
    roots = [Path(root) for root in roots]
    Image = pillow_image_module()  # the texture limits for the images trimesh opens
    try:
        with _quiet_trimesh(), warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            data = read_asset_file(path, what, MAX_MESH_FILE_BYTES)
            return _load_model(path, data, what, roots, materials, trimesh, variant)
    except MemoryError:
        raise AssetError(f"{what}: does not fit in memory") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise AssetError(f"{what}: an image it names declares more pixels than a texture may have "
                         f"({MAX_TEXTURE_SIDE}x{MAX_TEXTURE_SIDE})") from None


def _load_model(path: Path, data: bytes, what: str, roots, materials: bool, trimesh,
                variant: str | None = None) -> LoadedModel:
    suffix = path.suffix.lower()
    gltf = obj = None
    try:
        if suffix in (".gltf", ".glb"):
            gltf = prepare_gltf(path, data, roots, materials, variant)
            body, resolver = gltf.data, gltf.resolver
        elif suffix == ".obj":
            obj = prepare_obj(path, data, roots, materials)
            body, resolver = obj.text, obj.resolver
    except AssetError as exc:
        if str(exc).startswith(what):
            raise
        raise AssetError(f"{what}: {exc}") from exc
    if gltf is None and obj is None:  # PLY, STL, OFF: a PLY's TextureFile is not served (never drawn)
        body, resolver = data, CheckedFiles(path.name)
    del data
    try:  # before trimesh parses the file: a node naming a camera it lacks would be its IndexError
        lights = read_gltf_lights(gltf.doc) if gltf is not None else []
        cameras = read_gltf_cameras(gltf.doc) if gltf is not None else []
        variants = variant_names(gltf.doc) if gltf is not None else []
    except AssetError as exc:
        raise AssetError(f"{what}: {exc}") from exc
    try:
        loaded = trimesh.load(io.BytesIO(body), file_type=suffix[1:], resolver=resolver, force="scene",
                              process=False)
    except MemoryError:
        raise
    except Exception as exc:  # trimesh raises many kinds for corrupt files
        raise AssetError(f"{what}: cannot be parsed ({type(exc).__name__}: {exc})") from exc
    del body
    parts: list[ModelPart] = []
    meshes: dict = {}  # geometry name, then content digest -> the one Mesh
    # The nodes a clip moves (itself or an ancestor animated): one scaled to nothing at rest
    # is kept, hidden, for a clip that grows it.
    animated = {node for clip in gltf.animations for node in moved_nodes(gltf.node_tree, clip)} \
        if gltf is not None and gltf.animations else set()
    try:
        maps = _MaterialMaps(path, gltf, obj)
        for node in loaded.graph.nodes_geometry:
            matrix, geom_name = loaded.graph[node]
            tm = loaded.geometry[geom_name]
            if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
                continue
            matrix = np.asarray(matrix, np.float64)
            shown = gltf.node_name(node) if gltf is not None else node
            if not np.isfinite(matrix).all():
                raise AssetError(f"node {shown!r} has a NaN or infinite transform")
            index = gltf.node(node) if gltf is not None else None
            skin = gltf.skin_of(index) if gltf is not None else None
            hidden = skin is None and collapsed(matrix)  # (a skinned node's own transform is left out)
            if hidden and index not in animated:
                continue  # scaled to nothing (files hide nodes this way), no clip grows it: it would draw nothing
            if np.abs(matrix).max() > 1e18:
                # Past float32 once multiplied out (vertex x scale x parents): refuse here, by node.
                raise AssetError(f"node {shown!r} has a transform too large for float32 rendering "
                                 f"(largest entry {np.abs(matrix).max():.3g}, limit 1e18)")
            name = f"{path.name}:{geom_name}"
            morph_weights = gltf.morph_weights(index) if gltf is not None else None
            mesh = meshes.get(("geometry", geom_name, skin))
            kept = getattr(tm, "vertex_attributes", {})  # (as trimesh kept them: a vertex each)
            # its UV sets past the first (glTF's TEXCOORD_1...: engine/assets/gltf_uv_sets.py)
            sets = uv_sets(kept, len(tm.vertices), f"node {shown!r}'s mesh") if gltf is not None else {}
            if mesh is None:
                mesh = Mesh.from_trimesh(tm, name=name, srgb_colors=suffix not in (".gltf", ".glb"))
                joints = weights = offsets = normal_offsets = None
                if skin is not None:  # its joints and weights a vertex
                    joints, weights = skin_arrays(kept, len(mesh.positions), gltf.skins[skin], f"node {shown!r}'s mesh")
                if morph_weights is not None:  # its morph targets' offsets
                    offsets, normal_offsets = morph_arrays(kept, len(mesh.positions), len(morph_weights),
                                                           f"node {shown!r}'s mesh")
                if skin is not None or morph_weights is not None or 1 in sets:  # (a mesh keeps its TEXCOORD_1)
                    mesh = Mesh(mesh.positions, mesh.normals, mesh.uvs, mesh.indices, name=name, colors=mesh.colors,
                                joints=joints, weights=weights, morph_positions=offsets, morph_normals=normal_offsets,
                                second_uvs=sets.get(1))
                mesh = meshes.setdefault(("content", _digest(mesh)), mesh)
                meshes[("geometry", geom_name, skin)] = mesh
            if skin is not None:  # glTF: a skinned node's own transform is left out (its joints place it)
                matrix = np.eye(4)
            part = ModelPart(mesh=mesh, local=glm.mat4(*matrix.astype(np.float32).T.ravel()), name=name,
                             node=index, skin=skin, morph_weights=morph_weights, hidden=hidden)
            if materials:
                _read_material(tm, part, path, maps)
                maps.read(tm, part, sets)
            if gltf is not None:
                part.material = gltf.material(getattr(getattr(tm.visual, "material", None), "name", None))[0]
            parts.append(part)
    except AssetError as exc:
        raise AssetError(f"{what}: {exc}") from exc
    except MemoryError:
        raise
    except Exception as exc:  # trimesh computing normals/visuals of malformed data
        raise AssetError(f"{what}: holds malformed mesh data ({type(exc).__name__}: {exc})") from exc
    if not parts:
        raise AssetError(f"{what}: contains no triangle meshes")
    if variant and gltf is None:
        raise AssetError(f"{what}: has no material variant {variant!r} (only a glTF file has variants)")
    clips = gltf.animations if gltf is not None else []
    skins = gltf.skins if gltf is not None else []
    return LoadedModel(parts, lights, cameras, variants, clips, gltf.node_tree if clips or skins else None, skins,
                       sorted(resolver.side_files))


def _digest(mesh: Mesh) -> bytes:
    """What makes two meshes the same geometry: their arrays, byte for byte."""
    digest = hashlib.blake2b(digest_size=20)
    for array in (mesh.positions, mesh.normals, mesh.uvs, mesh.indices,
                  mesh.colors if mesh.colors is not None else np.zeros(0, np.float32),
                  mesh.joints if mesh.joints is not None else np.zeros(0, np.uint16),
                  mesh.weights if mesh.weights is not None else np.zeros(0, np.float32),
                  mesh.morph_positions if mesh.morph_positions is not None else np.zeros(0, np.float32),
                  mesh.morph_normals if mesh.morph_normals is not None else np.zeros(0, np.float32),
                  mesh.second_uvs if mesh.second_uvs is not None else np.zeros(0, np.float32)):
        digest.update(np.asarray(array.shape, np.int64).tobytes())
        digest.update(memoryview(array).cast("B"))
    return digest.digest()


def model_bytes(parts: Sequence[ModelPart]) -> int:
    """What a loaded model's meshes and textures take on the CPU, each shared one once (what
    a level's memory budget counts for it)."""
    seen: set[int] = set()
    total = 0
    for part in parts:
        mesh = part.mesh
        if id(mesh) not in seen:
            seen.add(id(mesh))
            total += mesh.positions.nbytes + mesh.normals.nbytes + mesh.uvs.nbytes + mesh.indices.nbytes
            total += mesh.colors.nbytes if mesh.colors is not None else 0
            total += mesh.joints.nbytes + mesh.weights.nbytes if mesh.joints is not None else 0
            total += sum(a.nbytes for a in (mesh.morph_positions, mesh.morph_normals, mesh.second_uvs) if a is not None)
        for texture in (part.texture, part.normal_map, part.emissive_map, part.metallic_roughness_map,
                        part.occlusion_map):
            if texture is not None and id(texture) not in seen:
                seen.add(id(texture))
                total += texture.pixels.nbytes
    return total


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


def _unit_color(value) -> np.ndarray:
    """A colour from trimesh (uint8 0..255 or float 0..1) as float RGBA."""
    c = np.asarray(value)
    c = c.astype(np.float64) / 255.0 if c.dtype.kind in "ui" else c.astype(np.float64)
    if len(c) == 3:
        c = np.append(c, 1.0)
    return c[:4]


def _read_material(tm, part: ModelPart, path: Path, maps: _MaterialMaps) -> None:
    """Fill colour, texture, PBR factors and the emissive factor from trimesh's visual."""
    from trimesh.visual.material import SimpleMaterial

    image_what = f"texture of {str(path)!r}"
    visual = getattr(tm, "visual", None)
    material = getattr(visual, "material", None)
    if isinstance(material, SimpleMaterial) and not (material.kwargs or getattr(material, "_name", None)):
        # trimesh's placeholder for UVs without any material (a 2x2 grey image): the file has
        # no material, so the engine's defaults apply.
        material = None
    if material is None:
        if getattr(visual, "kind", None) in ("vertex", "face"):
            part.color = (1.0, 1.0, 1.0, 1.0)  # the mesh's own colours, a vertex or a face (Mesh.colors)
        return
    if hasattr(material, "baseColorFactor"):  # glTF PBR
        base = maps.gltf_base_color(material)   # (the file's floats; trimesh's are 8 bits)
        if base is None and material.baseColorFactor is not None:
            base = _unit_color(material.baseColorFactor)
        if base is not None:
            part.color = tuple(float(c) for c in base)
        image = maps.gltf_image(material, "baseColorTexture")
        maps.check_gltf_slot(material, "baseColorTexture", image)
        image_what = f"{maps.gltf_label(material)}: baseColorTexture"
        # glTF's defaults are 1.0; trimesh reports an absent factor as None.  The engine
        # keeps its own defaults (dielectric, 0.5) for a file that says nothing.
        part.metallic = float(material.metallicFactor if material.metallicFactor is not None else 0.0)
        part.roughness = float(material.roughnessFactor if material.roughnessFactor is not None else 0.5)
        emissive = _floats(material.emissiveFactor)
        part.emissive_strength = maps.gltf_emissive_strength(material)
        if emissive is not None:  # KHR_materials_emissive_strength: how far past 1 it glows
            part.emissive_rgb = tuple(float(e) for e in (list(emissive[:3]) + [0.0, 0.0, 0.0])[:3])
            emissive = [e * part.emissive_strength for e in emissive]
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
        wanted = maps.mtl_map(material, "map_kd")
        if wanted is not None:
            image_what = f"{wanted.where}: the image {wanted.name!r} of material {material.name!r}"
            if image is None:
                raise AssetError(f"{image_what}: cannot be decoded as an image")
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
        part.texture = maps.image(image, image_what, "colour")
    if hasattr(material, "baseColorFactor"):
        _gltf_alpha(material, part, maps.gltf_label(material))
        part.double_sided = bool(getattr(material, "doubleSided", False))
    for name in ("metallic", "roughness", "reflectivity"):
        value = getattr(part, name)
        if not (np.isfinite(value) and 0.0 <= value <= 1.0):
            raise AssetError(f"material {name} {value} is outside 0..1")


def _texture_number(doc_material: dict, slot: str, key: str, high: float, what: str) -> float:
    """A number of a material's texture slot as the file writes it (``normalTexture.scale``,
    ``occlusionTexture.strength``: trimesh drops them), in [0, ``high``]; 1 when absent."""
    info = doc_material.get(slot) if isinstance(doc_material, dict) else None
    value = info.get(key, 1.0) if isinstance(info, dict) else 1.0
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0.0 <= float(value) <= high:
        raise AssetError(f"{what}: {slot}.{key} must be a number in [0, {high:g}], got {value!r}")
    return float(value)


BLENDED_ALPHA = 0.999  # a glTF BLEND material's alpha where its factor's is 1: the transparent slot's
MTL_DISSOLVE_CUTOFF = 0.5  # an opaque OBJ material with a map_d: a cutout at this alpha


def _gltf_alpha(material, part: ModelPart, what: str) -> None:
    """What glTF's ``alphaMode`` makes of a material's alpha (the colour's times the
    texture's): OPAQUE (the default) ignores it, so the part is opaque whatever its alpha;
    MASK cuts it at ``alphaCutoff`` (default 0.5: ``Material.alpha_cutoff``); BLEND blends
    it, so a part whose factor's alpha is 1 but whose texture has see-through texels, or
    whose COLOR_0 a see-through vertex, goes to the transparent slot too (its colour's alpha
    just under 1, as world text's)."""
    mode = getattr(material, "alphaMode", None) or "OPAQUE"
    if mode not in ("OPAQUE", "MASK", "BLEND"):
        raise AssetError(f"{what}: alphaMode must be OPAQUE, MASK or BLEND, got {mode!r}")
    if mode == "OPAQUE":
        part.color = (*part.color[:3], 1.0)
    elif mode == "MASK":
        cutoff = getattr(material, "alphaCutoff", None)
        cutoff = 0.5 if cutoff is None else cutoff
        if isinstance(cutoff, (bool, str)) or not isinstance(cutoff, numbers.Real) or \
                not (np.isfinite(cutoff) and 0.0 <= cutoff <= 1.0):
            raise AssetError(f"{what}: alphaCutoff must be a number in [0, 1] (above 1 nothing would be drawn), "
                             f"got {cutoff!r}")
        part.alpha_cutoff = float(cutoff)
    elif part.color[3] >= 1.0 and ((part.texture is not None and part.texture.has_alpha) or part.mesh.has_alpha):
        part.color = (*part.color[:3], BLENDED_ALPHA)


def _gltf_transmission(doc_material: dict, part: ModelPart, what: str) -> None:
    """Glass from a glTF material: ``KHR_materials_transmission``'s factor (the share of the
    light that passes through, tinted by the base colour), ``KHR_materials_ior``'s index,
    whether ``KHR_materials_volume`` gives it a thickness (a solid; without it glTF's
    transmission is a thin wall) and ``KHR_materials_dispersion``'s spread of the colours.
    A factor, index, thickness or dispersion out of range is an error naming the material;
    their textures are left out with a warning (one factor a part)."""
    extensions = doc_material.get("extensions") if isinstance(doc_material, dict) else None
    if not isinstance(extensions, dict):
        return
    found = {name: extensions.get(name) for name in ("KHR_materials_transmission", "KHR_materials_ior",
                                                     "KHR_materials_volume", "KHR_materials_dispersion")}
    for name, info in found.items():
        if info is not None and not isinstance(info, dict):
            raise AssetError(f"{what}: {name} must be an object, got {info!r}")
    transmission = found["KHR_materials_transmission"] or {}
    factor = transmission.get("transmissionFactor", 0.0)
    if isinstance(factor, bool) or not isinstance(factor, numbers.Real) or not 0.0 <= float(factor) <= 1.0:
        raise AssetError(f"{what}: KHR_materials_transmission.transmissionFactor must be a number in [0, 1], "
                         f"got {factor!r}")
    ior = (found["KHR_materials_ior"] or {}).get("ior", 1.5)
    if isinstance(ior, bool) or not isinstance(ior, numbers.Real) or not 1.0 <= float(ior) <= MAX_IOR:
        raise AssetError(f"{what}: KHR_materials_ior.ior must be a number in [1, {MAX_IOR:g}] (Refractive.ior), "
                         f"got {ior!r}")
    thickness = (found["KHR_materials_volume"] or {}).get("thicknessFactor", 0.0)
    if isinstance(thickness, bool) or not isinstance(thickness, numbers.Real) or \
            not (math.isfinite(thickness) and thickness >= 0.0):
        raise AssetError(f"{what}: KHR_materials_volume.thicknessFactor must be a number >= 0, got {thickness!r}")
    dispersion = (found["KHR_materials_dispersion"] or {}).get("dispersion", 0.0)
    if isinstance(dispersion, bool) or not isinstance(dispersion, numbers.Real) or \
            not 0.0 <= float(dispersion) <= MAX_DISPERSION:
        raise AssetError(f"{what}: KHR_materials_dispersion.dispersion must be a number in [0, {MAX_DISPERSION:g}] "
                         f"(Refractive.dispersion), got {dispersion!r}")
    for name, slot in (("KHR_materials_transmission", "transmissionTexture"),
                       ("KHR_materials_volume", "thicknessTexture")):
        if slot in (found[name] or {}) and factor > 0.0:
            warnings.warn(f"{what}: {name}.{slot} is left out: the part lets through its factor's share "
                          "everywhere", stacklevel=6)
    part.transmission, part.ior, part.thick = float(factor), float(ior), thickness > 0.0
    part.dispersion = float(dispersion)
    if factor > 0.0 and thickness > 0.0:
        _gltf_attenuation(found["KHR_materials_volume"], float(thickness), part, what)


def _gltf_attenuation(volume: dict, thickness: float, part: ModelPart, what: str) -> None:
    """Coloured glass: ``KHR_materials_volume``'s attenuation (Beer-Lambert: what passes keeps
    ``attenuationColor`` once every ``attenuationDistance``), over the volume's
    ``thicknessFactor``, as the glTF sample viewer tints a thick part's transmitted light:
    ``attenuationColor ^ (thickness / attenuationDistance)``, multiplied into the colour that
    tints what the glass lets through (the engine's glass has no path length of its own)."""
    colour = volume.get("attenuationColor", [1.0, 1.0, 1.0])
    if not (isinstance(colour, list) and len(colour) == 3 and all(
            isinstance(c, numbers.Real) and not isinstance(c, bool) and 0.0 <= c <= 1.0 for c in colour)):
        raise AssetError(f"{what}: KHR_materials_volume.attenuationColor must be three numbers in [0, 1], "
                         f"got {colour!r}")
    distance = volume.get("attenuationDistance", math.inf)
    if isinstance(distance, bool) or not isinstance(distance, numbers.Real) or not distance > 0.0:
        raise AssetError(f"{what}: KHR_materials_volume.attenuationDistance must be a number > 0, got {distance!r}")
    if math.isinf(distance):
        return  # (glTF's default: nothing absorbed)
    kept = [float(c) ** (thickness / float(distance)) for c in colour]
    part.color = (*(base * k for base, k in zip(part.color[:3], kept, strict=True)), part.color[3])


def _gltf_reflectance(doc_material: dict, part: ModelPart, what: str) -> None:
    """What a glTF material's non-metal reflects head on, as ``Material.reflectance`` (f0 =
    0.16 r^2) and ``Material.specular_color`` (its tint): ``KHR_materials_ior``'s index as
    Schlick's f0 (``f0_from_ior``; part.ior, read with the glass) times
    ``KHR_materials_specular``'s colour, each channel held at 1, times its factor (glTF's
    ``min(f0 x specularColorFactor, 1) x specularFactor``): the reflectance from the largest
    channel (up to 16%), the tint the channels over it.  Its textures are left out with a
    warning."""
    extensions = doc_material.get("extensions") if isinstance(doc_material, dict) else None
    specular = extensions.get("KHR_materials_specular") if isinstance(extensions, dict) else None
    if specular is not None and not isinstance(specular, dict):
        raise AssetError(f"{what}: KHR_materials_specular must be an object, got {specular!r}")
    specular = specular or {}
    factor = specular.get("specularFactor", 1.0)
    if isinstance(factor, bool) or not isinstance(factor, numbers.Real) or not 0.0 <= float(factor) <= 1.0:
        raise AssetError(f"{what}: KHR_materials_specular.specularFactor must be a number in [0, 1], got {factor!r}")
    colour = specular.get("specularColorFactor", [1.0, 1.0, 1.0])
    if not (isinstance(colour, list) and len(colour) == 3 and all(
            isinstance(c, numbers.Real) and not isinstance(c, bool) and math.isfinite(c) and c >= 0.0 for c in colour)):
        raise AssetError(f"{what}: KHR_materials_specular.specularColorFactor must be three numbers >= 0, "
                         f"got {colour!r}")
    f0_ior = f0_from_ior(part.ior)
    f0 = [min(f0_ior * float(c), 1.0) * float(factor) for c in colour]
    left = [slot for slot in ("specularTexture", "specularColorTexture") if slot in specular]
    if left:
        warnings.warn(f"{what}: KHR_materials_specular's {', '.join(left)} left out", stacklevel=6)
    grey = min(max(f0), 0.16)
    part.reflectance = math.sqrt(grey / 0.16)
    part.specular_color = tuple(c / grey for c in f0) if grey > 0.0 else (1.0, 1.0, 1.0)


def _gltf_extension(doc_material: dict, name: str, what: str) -> dict | None:
    """A glTF material's extension object ``name`` (None: it has none); not an object is an
    error naming the material."""
    extensions = doc_material.get("extensions") if isinstance(doc_material, dict) else None
    info = extensions.get(name) if isinstance(extensions, dict) else None
    if info is not None and not isinstance(info, dict):
        raise AssetError(f"{what}: {name} must be an object, got {info!r}")
    return info


def _gltf_number(info: dict, name: str, key: str, default: float, low: float, high: float, what: str) -> float:
    """An extension's number ``key`` (``default`` where left out) in [low, high], or an error
    naming the material, the extension and the key."""
    value = info.get(key, default)
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not low <= float(value) <= high:
        raise AssetError(f"{what}: {name}.{key} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def _gltf_textures_left_out(info: dict, name: str, slots: tuple[str, ...], used: bool, what: str, why: str) -> None:
    """Warn that an extension's textures (``slots`` it has) are left out, where it is ``used``."""
    left = [slot for slot in slots if slot in info]
    if left and used:
        warnings.warn(f"{what}: {name}'s {', '.join(left)} left out: {why}", stacklevel=7)


def _gltf_clearcoat(doc_material: dict, part: ModelPart, what: str) -> None:
    """A glTF material's clear coat (``KHR_materials_clearcoat``): its factor and roughness
    factor (``Material.clearcoat``, ``clearcoat_roughness``); a factor out of [0, 1] is an
    error naming the material; its textures are left out with a warning (one coat a part, on
    the mesh's own normal)."""
    name = "KHR_materials_clearcoat"
    info = _gltf_extension(doc_material, name, what)
    if info is None:
        return
    part.clearcoat = _gltf_number(info, name, "clearcoatFactor", 0.0, 0.0, 1.0, what)
    part.clearcoat_roughness = _gltf_number(info, name, "clearcoatRoughnessFactor", 0.0, 0.0, 1.0, what)
    _gltf_textures_left_out(info, name, ("clearcoatTexture", "clearcoatRoughnessTexture", "clearcoatNormalTexture"),
                            part.clearcoat > 0.0, what, "the coat is its factors' everywhere, on the mesh's own normal")


def _gltf_sheen(doc_material: dict, part: ModelPart, what: str) -> None:
    """A glTF material's sheen (``KHR_materials_sheen``): its colour and roughness factors
    (``Material.sheen_color``, ``sheen_roughness``); a factor out of [0, 1] is an error
    naming the material; its textures are left out with a warning (one sheen a part)."""
    name = "KHR_materials_sheen"
    info = _gltf_extension(doc_material, name, what)
    if info is None:
        return
    colour = info.get("sheenColorFactor", [0.0, 0.0, 0.0])
    if not (isinstance(colour, list) and len(colour) == 3 and all(
            not isinstance(c, bool) and isinstance(c, numbers.Real) and 0.0 <= float(c) <= 1.0 for c in colour)):
        raise AssetError(f"{what}: {name}.sheenColorFactor must be three numbers in [0, 1], got {colour!r}")
    part.sheen_color = tuple(float(c) for c in colour)
    part.sheen_roughness = _gltf_number(info, name, "sheenRoughnessFactor", 0.0, 0.0, 1.0, what)
    _gltf_textures_left_out(info, name, ("sheenColorTexture", "sheenRoughnessTexture"), max(colour) > 0.0, what,
                            "the sheen is its factors' everywhere")


def _gltf_diffuse_transmission(doc_material: dict, part: ModelPart, what: str) -> None:
    """A glTF material's diffuse transmission (``KHR_materials_diffuse_transmission``): its
    factor and colour factor (``Material.diffuse_transmission``, ``diffuse_transmission_color``);
    a factor out of [0, 1] is an error naming the material; its textures are left out with a
    warning."""
    name = "KHR_materials_diffuse_transmission"
    info = _gltf_extension(doc_material, name, what)
    if info is None:
        return
    part.diffuse_transmission = _gltf_number(info, name, "diffuseTransmissionFactor", 0.0, 0.0, 1.0, what)
    colour = info.get("diffuseTransmissionColorFactor", [1.0, 1.0, 1.0])
    if not (isinstance(colour, list) and len(colour) == 3 and all(
            not isinstance(c, bool) and isinstance(c, numbers.Real) and 0.0 <= float(c) <= 1.0 for c in colour)):
        raise AssetError(f"{what}: {name}.diffuseTransmissionColorFactor must be three numbers in [0, 1], "
                         f"got {colour!r}")
    part.diffuse_transmission_color = tuple(float(c) for c in colour)
    _gltf_textures_left_out(info, name, ("diffuseTransmissionTexture", "diffuseTransmissionColorTexture"),
                            part.diffuse_transmission > 0.0, what, "it passes its factors' light everywhere")


def _gltf_anisotropy(doc_material: dict, part: ModelPart, what: str) -> None:
    """A glTF material's anisotropy (``KHR_materials_anisotropy``): its strength and rotation
    (radians, counter-clockwise from the UVs' u: ``Material.anisotropy``,
    ``anisotropy_direction`` in degrees); a strength out of [0, 1] or a rotation that is not a
    finite number is an error naming the material; its texture is left out with a warning."""
    name = "KHR_materials_anisotropy"
    info = _gltf_extension(doc_material, name, what)
    if info is None:
        return
    part.anisotropy = _gltf_number(info, name, "anisotropyStrength", 0.0, 0.0, 1.0, what)
    rotation = info.get("anisotropyRotation", 0.0)
    if isinstance(rotation, bool) or not isinstance(rotation, numbers.Real) or not math.isfinite(rotation):
        raise AssetError(f"{what}: {name}.anisotropyRotation must be a finite number (radians), got {rotation!r}")
    part.anisotropy_direction = math.degrees(math.remainder(float(rotation), 2.0 * math.pi))
    _gltf_textures_left_out(info, name, ("anisotropyTexture",), part.anisotropy > 0.0, what,
                            "the anisotropy is its strength and rotation everywhere")


def _gltf_iridescence(doc_material: dict, part: ModelPart, what: str) -> None:
    """A glTF material's thin film (``KHR_materials_iridescence``): its factor, index and
    thickness (the maximum: without its thickness texture glTF's film is that thick
    everywhere); a value out of range is an error naming the material; the textures are left
    out with a warning."""
    name = "KHR_materials_iridescence"
    info = _gltf_extension(doc_material, name, what)
    if info is None:
        return
    part.iridescence = _gltf_number(info, name, "iridescenceFactor", 0.0, 0.0, 1.0, what)
    part.iridescence_ior = _gltf_number(info, name, "iridescenceIor", 1.3, 1.0, MAX_IOR, what)
    part.iridescence_thickness = _gltf_number(info, name, "iridescenceThicknessMaximum", 400.0, 0.0,
                                              MAX_FILM_THICKNESS, what)
    _gltf_textures_left_out(info, name, ("iridescenceTexture", "iridescenceThicknessTexture"), part.iridescence > 0.0,
                            what, "the film is its factor's, its index's and its maximum thickness's everywhere")


# --- material maps -----------------------------------------------------------------------

class _MaterialMaps:
    """The material maps of a file's parts: the albedo texture, and normal, emissive and
    metallic-roughness maps (glTF through trimesh's PBRMaterial, matched to the file's JSON by
    the index ``prepare_gltf`` wrote into its name, for ``normalTexture.scale``, which trimesh
    drops; OBJ from the MTL statements ``prepare_obj`` read).  One image is one TextureData
    however many parts use it, so it is decoded and uploaded once; only the maps of the
    materials the faces use are read at all."""

    def __init__(self, path: Path, gltf: GltfFiles | None, obj: ObjFiles | None) -> None:
        self.path = path
        self.gltf = gltf
        self.obj = obj
        self._made: dict[tuple, TextureData] = {}

    def read(self, tm: trimesh.Trimesh, part: ModelPart, sets: dict[int, np.ndarray] | None = None) -> None:
        """Fill ``part``'s material from the one trimesh read for ``tm``; a glTF's maps get the
        UV sets they read (``sets``: the primitive's past the first, ``gltf_uv_sets.uv_sets``)."""
        from trimesh.visual.material import SimpleMaterial

        material = getattr(getattr(tm, "visual", None), "material", None)
        if material is None:
            return
        if hasattr(material, "baseColorFactor"):
            self._gltf(material, part)
            index, _ = self.gltf.material(material.name) if self.gltf else (None, {})
            plan = self.gltf.uv_plans.get(index) if self.gltf else None
            if plan is not None:
                self._plan_uvs(part, plan, sets or {}, self.gltf_label(material))
        elif isinstance(material, SimpleMaterial):
            found = self.obj.maps.get(getattr(material, "_name", None) or "") if self.obj else None
            if found:
                extra = {str(k).lower(): v for k, v in (getattr(material, "kwargs", {}) or {}).items()}
                self._obj(found, extra, part)

    def _plan_uvs(self, part: ModelPart, plan: UvPlan, sets: dict[int, np.ndarray], label: str) -> None:
        """``part``'s mesh made with the two UV sets its material's maps read (``plan``,
        ``engine/assets/gltf_uv_sets.py``): the first moved by its transform, the second the set
        and transform of the maps it names in ``second_uv_maps`` (their Material fields); made
        once a mesh, plan and sets.  (``prepare_gltf`` left out a map reading a set some
        primitive of its material lacks.)"""
        mesh = part.mesh

        def made_from(used: UvSource) -> np.ndarray:
            number, transform = used
            uvs = mesh.uvs if number == 0 else sets.get(number)
            if uvs is None:  # (prepare_gltf checked every primitive of the material has it)
                raise AssetError(f"{label}: its maps read TEXCOORD_{number}, which mesh {mesh.name!r} does not have")
            return moved_uvs(uvs, transform)

        numbers = sorted({plan.first[0], *((plan.second[0],) if plan.second is not None else ())} - {0})
        read = tuple(hashlib.blake2b(sets[n].tobytes(), digest_size=16).digest() if n in sets else None
                     for n in numbers)  # (the sets themselves: meshes alike but for a third set are one mesh)
        key = ("uv plan", id(mesh), plan, read)
        made = self._made.get(key)
        if made is None:
            made = self._made[key] = Mesh(
                mesh.positions, mesh.normals, made_from(plan.first), mesh.indices, name=mesh.name, colors=mesh.colors,
                joints=mesh.joints, weights=mesh.weights, morph_positions=mesh.morph_positions,
                morph_normals=mesh.morph_normals,
                second_uvs=made_from(plan.second) if plan.second is not None else mesh.second_uvs)
        part.mesh = made
        part.second_uv_maps = plan.second_maps

    def mtl_map(self, material, key: str) -> MtlMap | None:
        """The ``key`` map statement of the OBJ material trimesh calls ``material``."""
        found = self.obj.maps.get(getattr(material, "_name", None) or "") if self.obj else None
        return (found or {}).get(key)

    def gltf_label(self, material) -> str:
        """The glTF material trimesh calls ``material`` as the file names it."""
        if self.gltf is None:
            return f"material {material.name!r}"
        index, _ = self.gltf.material(material.name)
        return self.gltf.label(index) if index is not None else f"material {material.name!r}"

    def gltf_base_color(self, material) -> list[float] | None:
        """The file's ``baseColorFactor`` of this material as it wrote it (None: it has none):
        trimesh keeps it in 8 bits, a step of 1/255 in linear light (18% of a dark 0.01)."""
        _, doc_material = self.gltf.material(material.name) if self.gltf else (None, {})
        pbr = doc_material.get("pbrMetallicRoughness") if isinstance(doc_material, dict) else None
        factor = pbr.get("baseColorFactor") if isinstance(pbr, dict) else None
        if factor is None:
            return None
        if not (isinstance(factor, list) and len(factor) == 4 and all(
                isinstance(c, numbers.Real) and not isinstance(c, bool) and math.isfinite(c) for c in factor)):
            raise AssetError(f"{self.gltf_label(material)}: baseColorFactor must be four finite numbers, "
                             f"got {factor!r}")
        return [float(c) for c in factor]

    def gltf_emissive_strength(self, material) -> float:
        """The file's ``KHR_materials_emissive_strength`` of this material (1 without it):
        Blender writes it for a lamp brighter than its emissive colour's 1."""
        _, doc_material = self.gltf.material(material.name) if self.gltf else (None, {})
        extensions = doc_material.get("extensions") if isinstance(doc_material, dict) else None
        info = extensions.get("KHR_materials_emissive_strength") if isinstance(extensions, dict) else None
        strength = info.get("emissiveStrength", 1.0) if isinstance(info, dict) else 1.0
        if isinstance(strength, bool) or not isinstance(strength, numbers.Real) or \
                not (math.isfinite(strength) and 0.0 <= strength <= 1e4):
            raise AssetError(f"{self.gltf_label(material)}: KHR_materials_emissive_strength.emissiveStrength must be "
                             f"a number in [0, 10000], got {strength!r}")
        return float(strength)

    def gltf_image(self, material, slot: str):
        """The image trimesh read for a glTF material's ``slot``, or None where the file's
        slot is one the engine leaves out (``GltfFiles.unread``: warned of when read)."""
        if self.gltf is not None:
            index, _ = self.gltf.material(material.name)
            if (index, slot) in self.gltf.unread:
                return None
        return getattr(material, slot, None)

    def check_gltf_slot(self, material, slot: str, image) -> None:
        """A slot the file fills whose image trimesh could not open is an error (it would be
        drawn without it: an emissive part glowing whole), named with the material."""
        if self.gltf is None or image is not None:
            return
        index, _ = self.gltf.material(material.name)
        source = self.gltf.slots.get(index, {}).get(slot) if index is not None else None
        if source is not None:
            images = self.gltf.doc.get("images") or []
            entry = images[source] if source < len(images) and isinstance(images[source], dict) else {}
            named = entry.get("uri") if isinstance(entry.get("uri"), str) and \
                not entry["uri"].startswith("data:") else None
            raise AssetError(f"{self.gltf.label(index)}: {slot}: image {source}"
                             f"{f' ({named!r})' if named else ''} cannot be read as an image")

    # --- glTF ------------------------------------------------------------------------------
    def _gltf(self, material, part: ModelPart) -> None:
        what = self.gltf_label(material)
        _, doc_material = self.gltf.material(material.name) if self.gltf else (None, {})
        part.normal_map = self._slot_map(material, "normalTexture", what, "normal")
        if part.normal_map is not None:
            part.normal_scale = _texture_number(doc_material, "normalTexture", "scale", MAX_MTL_BUMP_SCALE, what)
        part.metallic_roughness_map = self._slot_map(material, "metallicRoughnessTexture", what, "linear")
        if part.metallic_roughness_map is not None:
            # glTF: the factors multiply the texture (roughness G, metallic B); absent, they are 1.
            part.metallic = 1.0 if material.metallicFactor is None else float(material.metallicFactor)
            part.roughness = 1.0 if material.roughnessFactor is None else float(material.roughnessFactor)
            for name in ("metallic", "roughness"):
                value = getattr(part, name)
                if not (np.isfinite(value) and 0.0 <= value <= 1.0):
                    raise AssetError(f"{what}: {name}Factor {value} is outside 0..1")
            # Reflective where any texel is metal; the map's blue weighs the reflection per pixel.
            metal = part.metallic_roughness_map.pixels[..., 2].max() > 0
            part.reflectivity = part.metallic if metal else 0.0
        part.occlusion_map = self._slot_map(material, "occlusionTexture", what, "linear")
        if part.occlusion_map is not None:
            part.occlusion_strength = _texture_number(doc_material, "occlusionTexture", "strength", 1.0, what)
        image = self.gltf_image(material, "emissiveTexture")
        self.check_gltf_slot(material, "emissiveTexture", image)
        factor = _floats(material.emissiveFactor)
        if factor is not None:
            factor = [f * self.gltf_emissive_strength(material) for f in factor]
        if image is not None and factor is not None and len(factor) >= 3 and max(factor[:3]) > 0.0:
            self._emissive(part, self.image(image, f"{what}: emissiveTexture", "colour"), factor[:3], what)
        _gltf_transmission(doc_material, part, what)
        _gltf_clearcoat(doc_material, part, what)
        _gltf_sheen(doc_material, part, what)
        _gltf_diffuse_transmission(doc_material, part, what)
        _gltf_anisotropy(doc_material, part, what)
        _gltf_iridescence(doc_material, part, what)
        _gltf_reflectance(doc_material, part, what)
        extensions = doc_material.get("extensions") if isinstance(doc_material, dict) else None
        if isinstance(extensions, dict) and "KHR_materials_unlit" in extensions:
            # its base colour as it is (glTF: the other properties are a fallback's, for a
            # viewer without the extension): no reflection, glass or coat of theirs
            part.unlit = True
            part.metallic = part.reflectivity = part.transmission = part.clearcoat = 0.0
            part.sheen_color = (0.0, 0.0, 0.0)
            part.diffuse_transmission = 0.0

    def image(self, image, what: str, kind: str) -> TextureData:
        """A decoded image of the file as a TextureData (once per image and kind), its size
        checked from its header before it is decoded."""
        key = ("image", id(image), kind)
        texture = self._made.get(key)
        if texture is None:
            check_texture_size(*image.size, f"{what} of {str(self.path)!r}")
            try:
                pixels = image_to_rgba8(image, what)
            except (AssetError, MemoryError):
                raise
            except Exception as exc:
                raise AssetError(f"{what} cannot be decoded ({type(exc).__name__}: {exc})") from exc
            texture = self._made[key] = TextureData(pixels, name=f"{self.path.name}:{what.split(': ')[-1]}")
        return texture

    def _slot_map(self, material, slot: str, what: str, kind: str) -> TextureData | None:
        """The image of a glTF material's ``slot`` as a TextureData read as ``kind`` (None:
        the slot is empty, or left out: ``gltf_image``); a slot whose image could not be
        read is an error (``check_gltf_slot``)."""
        image = self.gltf_image(material, slot)
        self.check_gltf_slot(material, slot, image)
        return self.image(image, f"{what}: {slot}", kind) if image is not None else None

    def _emissive(self, part: ModelPart, texture: TextureData, factor: list[float], what: str) -> None:
        """An emissive map emitted at the factor's largest channel (``Emissive.power``); a
        factor that is not grey has its hue (factor / largest) multiplied into the texels, in
        linear light, so the emitted colour is the file's factor x texture."""
        if not all(np.isfinite(e) and 0.0 <= e <= 65504.0 for e in factor):
            raise AssetError(f"{what}: emissive colour {factor} must be finite and >= 0")
        strength = max(factor)
        hue = tuple(float(f) / strength for f in factor)
        if hue != (1.0, 1.0, 1.0):
            key = ("tinted", id(texture), hue)
            tinted = self._made.get(key)
            if tinted is None:
                tinted = self._made[key] = tint_srgb(texture, hue)
            texture = tinted
        part.emissive_map = texture
        part.emissive_factor = float(min(strength, 1e4))

    # --- OBJ / MTL -------------------------------------------------------------------------
    def _obj(self, found: dict[str, MtlMap], extra: dict, part: ModelPart) -> None:
        entry = found.get("norm") or found.get("bump")
        if entry is not None:
            texture = self._file(entry, True)
            if entry.key != "norm" and is_grey(texture):  # a height map: its slopes become normals
                key = ("heights", entry.path)
                if key not in self._made:
                    self._made[key] = height_to_normal_map(texture)
                texture = self._made[key]
            part.normal_map = texture
            part.normal_scale = 1.0 if entry.bump_scale is None else entry.bump_scale
        entry = found.get("map_d")
        if entry is not None:
            self._dissolve(part, self._file(entry, False), entry)
        entry = found.get("map_ke")
        if entry is not None:
            ke = _floats(extra.get("ke"))
            factor = [1.0, 1.0, 1.0] if ke is None else (ke * 3 if len(ke) == 1 else ke[:3])
            if max(factor) > 0.0:
                self._emissive(part, self._file(entry, False), factor, entry.where)

    def _dissolve(self, part: ModelPart, mask: TextureData, entry: MtlMap) -> None:
        """An MTL ``map_d`` (the dissolve map: a grey image, or one with alpha, whose alpha
        is used) multiplied into the albedo texture's alpha (a white one where the material
        has none), the mask resampled to the texture's size (nearest texel).  A material
        that is otherwise opaque (``d`` 1) becomes a cutout at ``MTL_DISSOLVE_CUTOFF``, as
        foliage and chains are drawn from such files (Sponza's leaves); with ``d`` below 1
        it stays blended, the map scaling its alpha."""
        key = ("dissolved", id(part.texture), str(entry.path))
        texture = self._made.get(key)
        if texture is None:
            masked = mask.as_8_bits()
            alpha = masked[..., 3] if mask.has_alpha else masked[..., 0]
            base = part.texture.as_8_bits().copy() if part.texture is not None else \
                np.full(alpha.shape + (4,), 255, np.uint8)
            height, width = base.shape[:2]
            if alpha.shape != (height, width):
                rows = np.arange(height) * alpha.shape[0] // height
                columns = np.arange(width) * alpha.shape[1] // width
                alpha = alpha[rows[:, None], columns[None, :]]
            base[..., 3] = (base[..., 3].astype(np.uint16) * alpha // 255).astype(np.uint8)
            name = f"{part.texture.name if part.texture is not None else 'white'} x {mask.name}"
            texture = self._made[key] = TextureData(base, name=name)
        part.texture = texture
        if part.color[3] >= 1.0:
            part.alpha_cutoff = MTL_DISSOLVE_CUTOFF

    def _file(self, entry: MtlMap, linear: bool) -> TextureData:
        key = ("file", str(entry.path), linear)
        texture = self._made.get(key)
        if texture is None:
            try:
                texture = self._made[key] = load_texture(entry.path, keep_16_bits=linear)
            except AssetError as exc:
                raise AssetError(f"{entry.where}: {exc}") from exc
        return texture


def tint_srgb(texture: TextureData, hue: Sequence[float], name: str | None = None) -> TextureData:
    """``texture`` (sRGB colour) with each channel multiplied by ``hue`` in linear light, as
    8 bits: through a 256-entry table per channel (sRGB byte -> linear x hue -> sRGB byte), a
    block of rows at a time, so it costs the output image and no per-texel float temporaries."""
    levels = srgb_to_linear(np.arange(256, dtype=np.float64) / 255.0)
    tables = [np.rint(linear_to_srgb(levels * float(h)) * 255.0).astype(np.uint8) for h in hue[:3]]
    source = texture.pixels
    out = np.empty(source.shape, np.uint8)
    rows = max(1, WORK_BLOCK // max(1, source.shape[1]))
    for top in range(0, source.shape[0], rows):
        block = source[top:top + rows]
        if block.dtype != np.uint8:
            block = ((block.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
        for channel, table in enumerate(tables):
            out[top:top + rows, :, channel] = table[block[..., channel]]
        out[top:top + rows, :, 3] = block[..., 3]
    return TextureData(out, name=name or f"{texture.name} x {[round(h, 4) for h in hue[:3]]}")


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


UV_FIT_TOLERANCE = 1e-3  # of the UVs' range: how far from an affine map of position they may be


def planar_uv_map(mesh: Mesh, second: bool = False) -> tuple[np.ndarray | None, str]:
    """The mesh's UVs (its second set, ``second``) as an affine function of model position,
    (2, 4) rows (u and v as ``dot(row.xyz, p) + row.w``), fitted to its vertices by least
    squares (on a flat mesh the part along the normal is the smallest); (None, why) when
    they are not one (a bumpy mirror's composite works its UVs out from the plane point it
    shades)."""
    points = np.hstack([mesh.positions.astype(np.float64), np.ones((len(mesh.positions), 1))])
    uvs = (mesh.second_uvs if second else mesh.uvs).astype(np.float64)
    rows, *_ = np.linalg.lstsq(points, uvs, rcond=None)  # (4, 2)
    span = float(np.ptp(uvs, axis=0).max())
    if not span > 0.0:
        return None, "its UVs do not vary"
    error = float(np.abs(points @ rows - uvs).max())
    if not error <= UV_FIT_TOLERANCE * span:
        return None, f"its UVs are off a plane map by {error:.3g}"
    return rows.T, ""
