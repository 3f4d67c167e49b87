"""glTF morph targets: a mesh's blend shapes and the weights it wears them at.

A primitive's ``targets`` each hold an offset a vertex for its POSITION (and NORMAL; a
TANGENT is left out: the engine has no tangent input), added to the mesh times the target's
weight: the mesh's ``weights`` by default, a node's own ``weights`` in place of them, a
clip's ``weights`` channel over time (``engine/assets/gltf_animations.py``).  Every
primitive of a mesh has as many targets (glTF), at most ``MAX_MORPH_TARGETS`` here.

Read before trimesh parses the file: trimesh reads no targets, but keeps a primitive's
attributes whose names start with "_" a vertex, so each target's offsets are named again as
``_SPECULUM_MORPH_POSITION_t`` and ``_SPECULUM_MORPH_NORMAL_t`` and read back in the order
trimesh keeps the vertices (``morph_arrays``); a sparse target (the usual way to store one
that moves a few vertices) is made dense first (``gltf_accessors.dense_sparse_accessors``).
"""
from __future__ import annotations

import math

import numpy as np

from components.limits import MAX_MORPH_TARGETS, MAX_MORPH_WEIGHT
from engine.core.errors import AssetError

POSITION_TAG = "_SPECULUM_MORPH_POSITION_"  # + target number: a target's POSITION as trimesh keeps it
NORMAL_TAG = "_SPECULUM_MORPH_NORMAL_"      # + target number: its NORMAL


def read_morphs(doc: dict, what: str) -> dict[int, tuple[float, ...]]:
    """Each mesh with morph targets (by index): its default weights; its primitives' targets
    renamed for trimesh to keep.  A mesh whose primitives differ in their targets' count,
    with more than MAX_MORPH_TARGETS, a target that is not an object of accessors, or weights
    (the mesh's or a node's) not one finite number a target, is an AssetError naming it."""
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    defaults: dict[int, tuple[float, ...]] = {}
    for index, mesh in enumerate(meshes):
        primitives = [p for p in (mesh.get("primitives") or []) if isinstance(p, dict)] if isinstance(mesh, dict) \
            else []
        counts = {len(p.get("targets") or []) if isinstance(p.get("targets") or [], list) else -1 for p in primitives}
        if counts <= {0}:
            continue
        label = f"{what}: mesh {index}" + (f" ({mesh['name']!r})" if isinstance(mesh.get("name"), str) else "")
        if len(counts) > 1 or -1 in counts:
            raise AssetError(f"{label}: its primitives' targets must be lists of one length (glTF), got lengths "
                             f"{sorted(counts)}")
        count = counts.pop()
        if count > MAX_MORPH_TARGETS:
            raise AssetError(f"{label}: has {count} morph targets; the engine weighs at most {MAX_MORPH_TARGETS} "
                             "(MAX_MORPH_TARGETS)")
        for number, primitive in enumerate(primitives):
            attributes = primitive.get("attributes")
            for t, target in enumerate(primitive["targets"]):
                if not isinstance(target, dict) or not isinstance(attributes, dict):
                    raise AssetError(f"{label}: primitive {number}'s target {t} must be an object of accessors, got "
                                     f"{target!r}")
                if "POSITION" in target:
                    attributes[f"{POSITION_TAG}{t}"] = target["POSITION"]
                if "NORMAL" in target:
                    attributes[f"{NORMAL_TAG}{t}"] = target["NORMAL"]
        defaults[index] = _weights(mesh.get("weights", [0.0] * count), count, f"{label}: weights")
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    for index, node in enumerate(nodes):
        if isinstance(node, dict) and "weights" in node:
            mesh = node.get("mesh")
            count = len(defaults.get(mesh, ())) if isinstance(mesh, int) and not isinstance(mesh, bool) else 0
            _weights(node["weights"], count, f"{what}: node {index}: weights")
    return defaults


def node_weights(doc: dict, node: int, defaults: dict[int, tuple[float, ...]]) -> tuple[float, ...] | None:
    """The weights node ``node`` wears its mesh's targets at (its own, else its mesh's; None:
    its mesh has no targets)."""
    entry = doc["nodes"][node]
    mesh = entry.get("mesh")
    if mesh not in defaults:
        return None
    return tuple(float(w) for w in entry["weights"]) if "weights" in entry else defaults[mesh]


def _weights(value: object, count: int, label: str) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != count or not all(
            isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and abs(w) <= MAX_MORPH_WEIGHT
            for w in value):
        raise AssetError(f"{label} must be {count} finite numbers within +-{MAX_MORPH_WEIGHT:g} (one a morph target), "
                         f"got {value!r}")
    return tuple(float(w) for w in value)


def morph_arrays(vertex_attributes: dict, vertices: int, count: int,
                 where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A primitive's targets' offsets (T, V, 3) for positions, and for normals (None: no target
    moves them), from the attributes trimesh kept; an offset array that is not three finite
    numbers a vertex is an AssetError naming ``where``."""
    positions = np.zeros((count, vertices, 3), np.float32)
    normals = np.zeros((count, vertices, 3), np.float32)
    any_normal = False
    for t in range(count):
        for tag, into in ((POSITION_TAG, positions), (NORMAL_TAG, normals)):
            offsets = vertex_attributes.get(f"{tag}{t}")
            if offsets is None:
                continue
            offsets = np.asarray(offsets)
            if offsets.shape != (vertices, 3) or not np.issubdtype(offsets.dtype, np.floating) \
                    or not np.isfinite(offsets).all():
                raise AssetError(f"{where}: morph target {t}'s {'POSITION' if tag == POSITION_TAG else 'NORMAL'} must "
                                 f"be three finite floats a vertex ({vertices}), got {offsets.dtype} {offsets.shape}")
            into[t] = offsets
            any_normal = any_normal or tag == NORMAL_TAG
    return positions, normals if any_normal else None
