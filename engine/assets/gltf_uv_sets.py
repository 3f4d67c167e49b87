"""glTF UV sets: which coordinates each map of a material reads, and the two a mesh carries.

A glTF map (a material's ``textureInfo``) reads the UV set its ``texCoord`` names
(TEXCOORD_0 by default), moved by its own ``KHR_texture_transform`` (offset, rotation,
scale; its ``texCoord`` overrides the map's).  The engine's mesh carries two sets
(``Mesh.uvs`` and ``Mesh.second_uvs``) and a material says which maps read the second
(``Material.second_uv_maps``), so each material's maps are grouped by the (set, transform)
they read (``plan_uv_sets``): the group holding TEXCOORD_0 (the most maps, else the base
colour's) becomes the first set, moved by its transform; one other group the second set, its
maps named in ``second_uv_maps``.  A third group cannot be drawn as the file means: its maps
are left out with a warning, as are maps of a ``texCoord`` that is no number.

Read before trimesh parses the file: trimesh reads TEXCOORD_0 alone (its v turned to count
up from the image's bottom), and keeps a primitive's attributes whose names start with "_" a
vertex in its order, so every other set is named again as ``_SPECULUM_TEXCOORD_n``
(``tag_uv_sets``) and read back by ``uv_sets``, turned the same way.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from engine.core.errors import AssetError

UV_TAG = "_SPECULUM_TEXCOORD_"  # + set number: a primitive's TEXCOORD_n (n >= 1) as trimesh keeps it

# A glTF material's map slots and the Material field each fills (in Material.MATERIAL_IMAGES' terms).
SLOT_FIELDS = {"baseColorTexture": "texture", "normalTexture": "normal_map", "emissiveTexture": "emissive_map",
               "metallicRoughnessTexture": "metallic_roughness_map", "occlusionTexture": "occlusion_map"}

Transform = tuple[float, float, float, float, float]  # offset x, offset y, rotation, scale x, scale y
UvSource = tuple[int, Transform | None]               # (TEXCOORD number, its transform; None: none)


@dataclass(frozen=True)
class UvPlan:
    """What a material's maps need of its meshes' two UV sets: the first (its TEXCOORD and
    transform), the second (None: none needed) and the maps that read the second, as
    Material fields."""

    first: UvSource
    second: UvSource | None = None
    second_maps: tuple[str, ...] = ()


def tag_uv_sets(doc: dict) -> None:
    """Name each primitive's TEXCOORD_n past the first again, for trimesh to keep (``UV_TAG``)."""
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    for mesh in meshes:
        for primitive in (mesh.get("primitives") or []) if isinstance(mesh, dict) else []:
            attributes = primitive.get("attributes") if isinstance(primitive, dict) else None
            if isinstance(attributes, dict):
                for name in [a for a in attributes if isinstance(a, str) and a.startswith("TEXCOORD_")]:
                    number = name[len("TEXCOORD_"):]
                    if number.isdigit() and int(number) > 0:
                        attributes[f"{UV_TAG}{int(number)}"] = attributes[name]


def uv_sets(vertex_attributes: dict, count: int, where: str) -> dict[int, np.ndarray]:
    """A primitive's UV sets past the first (set number -> float32 (V, 2), v counting up from
    the image's bottom as the engine's UVs do) from the attributes trimesh kept; a set that is
    not two finite numbers a vertex is an AssetError naming ``where``."""
    found: dict[int, np.ndarray] = {}
    for name, values in vertex_attributes.items():
        if not (isinstance(name, str) and name.startswith(UV_TAG)):
            continue
        number = int(name[len(UV_TAG):])
        values = np.asarray(values)
        if values.shape != (count, 2) or not np.issubdtype(values.dtype, np.number):
            raise AssetError(f"{where}: TEXCOORD_{number} must be two numbers a vertex ({count} vertices), got "
                             f"{values.dtype} {values.shape}")
        uvs = values.astype(np.float32)
        if not np.isfinite(uvs).all():
            raise AssetError(f"{where}: TEXCOORD_{number} has NaN or infinite values")
        uvs[:, 1] = 1.0 - uvs[:, 1]
        found[number] = uvs
    return found


def plan_uv_sets(uses: dict[str, UvSource]) -> tuple[UvPlan | None, dict[str, str]]:
    """The plan for a material whose map slots read ``uses`` (slot -> (TEXCOORD number, its
    transform)), and the slots left out, with why (a third (set, transform) pair).  None: its
    maps read TEXCOORD_0 as it is (nothing to change)."""
    if not uses:
        return None, {}
    counts = Counter(uses.values())
    order = list(SLOT_FIELDS)

    def rank(source: UvSource) -> tuple:
        # TEXCOORD_0 first (the set the engine's generated meshes and a model's other parts
        # read), then the most maps, then the earliest slot (the base colour's first)
        first_slot = min(order.index(slot) for slot, used in uses.items() if used == source)
        return source[0] != 0, -counts[source], first_slot

    groups = sorted(counts, key=rank)
    left_out = {slot: "a material's maps read two UV sets at most (a set with its transform is one), and "
                      f"its others read {_shown(groups[0])} and {_shown(groups[1])}"
                for slot, used in uses.items() if used in groups[2:]}
    first = groups[0]
    second = groups[1] if len(groups) > 1 else None
    if first == (0, None) and second is None:
        return None, left_out
    maps = tuple(SLOT_FIELDS[slot] for slot in order if slot in uses and uses[slot] == second)
    return UvPlan(first, second, maps), left_out


def _shown(source: UvSource) -> str:
    number, transform = source
    return f"TEXCOORD_{number}" + (" moved by a KHR_texture_transform" if transform is not None else "")


def moved_uvs(uvs: np.ndarray, transform: Transform | None) -> np.ndarray:
    """``uvs`` (the engine's: v up) moved by a glTF ``KHR_texture_transform`` (offset x,
    offset y, rotation, scale x, scale y): ``offset + R(rotation) (scale x uv)`` in glTF's UV
    space (v down from the image's top; the engine's v is 1 - that), R turning u towards -v:
    counter-clockwise as the UV square is drawn with v down, the image clockwise on the
    surface.  That is the direction of the extension's text and its example (offset (0, 1),
    a quarter turn and scale 0.5 show the image's lower left quarter turned clockwise) and of
    three.js's GLTFLoader (``Matrix3.setUvTransform``); the matrix in its GLSL listing,
    written as for v up, turns the other way (KhronosGroup/glTF issue 1563)."""
    if transform is None:
        return uvs
    ox, oy, rotation, sx, sy = transform
    c, s = math.cos(rotation), math.sin(rotation)
    u = uvs[:, 0].astype(np.float64) * sx
    v = (1.0 - uvs[:, 1].astype(np.float64)) * sy
    moved_u, moved_v = ox + c * u + s * v, oy - s * u + c * v
    return np.stack([moved_u, 1.0 - moved_v], axis=1).astype(np.float32)
