"""glTF skins: which nodes bend a mesh and how they sat when it was modelled.

A file's ``skins`` each name their joints (nodes) and, optionally, an inverse bind matrix a
joint (the inverse of the joint's place in the model when the mesh was bound to it; none:
the identity).  A node with a ``mesh`` and a ``skin`` draws that mesh bent by those joints:
a vertex follows its JOINTS_0 joints (indices into the skin's list) by its WEIGHTS_0.  Per
glTF, the skinned node's own transform is left out: the joints place the mesh.

Read before trimesh parses the file: trimesh reads neither skins nor JOINTS and WEIGHTS
(it keeps a primitive's attributes whose names start with "_" as vertex attributes, so each
primitive's sets are named again as ``_SPECULUM_JOINTS_n`` and ``_SPECULUM_WEIGHTS_n``,
read back a vertex in the order trimesh keeps them: ``skin_arrays``).  A joint's matrix in
a pose is its place in the model times its inverse bind matrix (``joint_matrices``), what
``Skin.joint_matrices`` holds (components/pose.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.limits import MAX_JOINTS
from engine.assets.gltf_accessors import BufferBytes, read_float_accessor
from engine.core.errors import AssetError

JOINTS_TAG = "_SPECULUM_JOINTS_"    # + set number: a primitive's JOINTS_n as trimesh keeps it
WEIGHTS_TAG = "_SPECULUM_WEIGHTS_"  # + set number: its WEIGHTS_n
MAX_INFLUENCE_SETS = 4              # JOINTS_0..3: sixteen joints a vertex at most (folded to four)


@dataclass
class SkinDef:
    """One of a file's skins: its ``name``, its ``joints`` (node indices) and each one's
    inverse bind matrix (J, 4, 4; points as columns)."""

    name: str
    joints: list[int]
    inverse_binds: np.ndarray


def read_skins(doc: dict, buffer_bytes: BufferBytes, what: str) -> list[SkinDef]:
    """The document's skins, checked (joints that are nodes of the file, at most MAX_JOINTS,
    one finite affine inverse bind matrix a joint), and each skinned primitive's joint and
    weight sets renamed for trimesh to keep.  A malformed skin, a node naming a skin the file
    lacks, or a skinned node's primitive without JOINTS_0 and WEIGHTS_0 is an AssetError
    naming it."""
    listed = doc.get("skins")
    if listed is None:
        listed = []
    if not isinstance(listed, list):
        raise AssetError(f"{what}: skins must be a list, got {listed!r}")
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    skins = [_skin(skin, index, nodes, doc, buffer_bytes, what) for index, skin in enumerate(listed)]
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    for index, node in enumerate(nodes):
        if not isinstance(node, dict) or "skin" not in node:
            continue
        skin = node["skin"]
        if isinstance(skin, bool) or not isinstance(skin, int) or not 0 <= skin < len(skins):
            raise AssetError(f"{what}: node {index} names skin {skin!r}, which the file does not have")
        mesh = node.get("mesh")
        if isinstance(mesh, int) and not isinstance(mesh, bool) and 0 <= mesh < len(meshes) \
                and isinstance(meshes[mesh], dict):
            for number, primitive in enumerate(meshes[mesh].get("primitives") or []):
                attributes = primitive.get("attributes") if isinstance(primitive, dict) else None
                if isinstance(attributes, dict) and not ("JOINTS_0" in attributes and "WEIGHTS_0" in attributes):
                    raise AssetError(f"{what}: node {index} is skinned (skin {skin}) but mesh {mesh}'s primitive "
                                     f"{number} has no JOINTS_0 and WEIGHTS_0 (glTF: a skinned mesh's vertices "
                                     "name their joints)")
    for mesh in meshes:
        for primitive in (mesh.get("primitives") or []) if isinstance(mesh, dict) else []:
            attributes = primitive.get("attributes") if isinstance(primitive, dict) else None
            if not isinstance(attributes, dict):
                continue
            for n in range(MAX_INFLUENCE_SETS):
                if f"JOINTS_{n}" in attributes and f"WEIGHTS_{n}" in attributes:
                    attributes[f"{JOINTS_TAG}{n}"] = attributes[f"JOINTS_{n}"]
                    attributes[f"{WEIGHTS_TAG}{n}"] = attributes[f"WEIGHTS_{n}"]
    return skins


def _skin(skin: object, index: int, nodes: list, doc: dict, buffer_bytes: BufferBytes, what: str) -> SkinDef:
    name = skin.get("name") if isinstance(skin, dict) else None
    label = f"{what}: skin {index}" + (f" ({name!r})" if isinstance(name, str) and name else "")
    if not isinstance(skin, dict):
        raise AssetError(f"{label}: must be an object, got {skin!r}")
    joints = skin.get("joints")
    if not isinstance(joints, list) or not joints:
        raise AssetError(f"{label}: joints must be a non-empty list of nodes, got {joints!r}")
    if len(joints) > MAX_JOINTS:
        raise AssetError(f"{label}: has {len(joints)} joints; the engine bends a mesh by at most {MAX_JOINTS} "
                         "(MAX_JOINTS: a row of the joint palette)")
    for joint in joints:
        if isinstance(joint, bool) or not isinstance(joint, int) or not 0 <= joint < len(nodes):
            raise AssetError(f"{label}: names joint node {joint!r}, which the file does not have")
    if len(set(joints)) != len(joints):
        raise AssetError(f"{label}: names a joint node twice ({joints})")
    if skin.get("inverseBindMatrices") is None:
        binds = np.tile(np.eye(4), (len(joints), 1, 1))
    else:
        values = read_float_accessor(doc, skin["inverseBindMatrices"], buffer_bytes, f"{label}: inverseBindMatrices")
        if values.shape != (len(joints), 16):
            raise AssetError(f"{label}: inverseBindMatrices must be {len(joints)} MAT4 (one a joint), got shape "
                             f"{values.shape}")
        binds = values.astype(np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)  # (glTF's are column-major)
        if not np.allclose(binds[:, 3], (0.0, 0.0, 0.0, 1.0), atol=1e-5):
            raise AssetError(f"{label}: an inverse bind matrix is not affine (its last row must be 0, 0, 0, 1)")
    return SkinDef(name if isinstance(name, str) and name else f"skin {index}", list(joints), binds)


def skin_arrays(vertex_attributes: dict, count: int, skin: SkinDef, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A primitive's joints and weights a vertex (every set side by side) from the attributes
    trimesh kept; a joint past the skin's list, or a count that is not the vertices', is an
    AssetError naming ``where``."""
    joints, weights = [], []
    for n in range(MAX_INFLUENCE_SETS):
        j, w = vertex_attributes.get(f"{JOINTS_TAG}{n}"), vertex_attributes.get(f"{WEIGHTS_TAG}{n}")
        if j is None or w is None:
            break
        j, w = np.asarray(j), np.asarray(w)
        if j.shape != (count, 4) or w.shape != (count, 4) or not np.issubdtype(j.dtype, np.integer):
            raise AssetError(f"{where}: JOINTS_{n} and WEIGHTS_{n} must be four integers and four weights a vertex "
                             f"({count} vertices), got {j.dtype} {j.shape} and {w.shape}")
        joints.append(j)
        weights.append(w)
    if not joints:
        raise AssetError(f"{where}: is skinned but has no JOINTS_0 and WEIGHTS_0")
    joints_all, weights_all = np.hstack(joints), np.hstack(weights).astype(np.float64)
    used = weights_all > 0.0
    if used.any() and int(joints_all[used].max()) >= len(skin.joints):
        raise AssetError(f"{where}: a vertex names joint {int(joints_all[used].max())} of skin {skin.name!r}, which "
                         f"has {len(skin.joints)}")
    return np.where(used, joints_all, 0), weights_all


def joint_matrices(skin: SkinDef, placed: np.ndarray) -> np.ndarray:
    """The skin's joint matrices (J, 4, 4, float32) with its joint nodes where ``placed``
    (every node's model-space matrix, ``gltf_animations.pose_all``) puts them: each one's
    place times its inverse bind matrix."""
    places = placed[skin.joints]
    return (places @ skin.inverse_binds).astype(np.float32)
