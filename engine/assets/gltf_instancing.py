"""glTF's ``EXT_mesh_gpu_instancing`` (a forest, a crowd of chairs: one mesh drawn at many
places, as Blender's and glTF-Transform's exporters write it) made plain nodes before trimesh
reads the file.

trimesh does not read the extension, so an instanced node would come in as one copy of its
mesh without a word.  Here each instanced node's TRANSLATION, ROTATION and SCALE accessors are
read and the node's mesh moves into one child node per instance, placed as the extension says
(the node's transform times the instance's); the children share the mesh, so the engine
uploads it once and draws the copies instanced, as it does any shared mesh.
"""
from __future__ import annotations

import numpy as np

from engine.assets.gltf_accessors import BufferBytes, read_float_accessor
from engine.core.errors import AssetError

MAX_GLTF_INSTANCES = 1 << 16  # instances a file may expand to (each is an entity once spawned)


def expand_gpu_instancing(doc: dict, buffer_bytes: BufferBytes, what: str) -> int:
    """Replace each ``EXT_mesh_gpu_instancing`` node's mesh by one child node a instance;
    how many instances were made.  A malformed one (no mesh, accessors of unequal counts or
    the wrong type, too many instances) is an AssetError naming the node."""
    nodes = doc.get("nodes")
    if not isinstance(nodes, list):
        return 0
    made = 0
    for index in range(len(nodes)):
        node = nodes[index]
        extensions = node.get("extensions") if isinstance(node, dict) else None
        info = extensions.get("EXT_mesh_gpu_instancing") if isinstance(extensions, dict) else None
        if info is None:
            continue
        label = f"{what}: node {index}: EXT_mesh_gpu_instancing"
        attributes = info.get("attributes") if isinstance(info, dict) else None
        if not isinstance(attributes, dict) or not attributes:
            raise AssetError(f"{label}: needs attributes (TRANSLATION, ROTATION, SCALE), got {info!r}")
        if "mesh" not in node:
            raise AssetError(f"{label}: the node has no mesh to instance")
        unknown = sorted(set(attributes) - {"TRANSLATION", "ROTATION", "SCALE"})
        if unknown and not all(name.startswith("_") for name in unknown):   # (custom "_ID" ones are allowed)
            raise AssetError(f"{label}: attributes {unknown} are not glTF's (TRANSLATION, ROTATION, SCALE)")
        values = {name: read_float_accessor(doc, attributes[name], buffer_bytes, f"{label}: {name}")
                  for name in ("TRANSLATION", "ROTATION", "SCALE") if name in attributes}
        counts = {len(v) for v in values.values()}
        if len(counts) != 1:
            raise AssetError(f"{label}: its attributes' counts differ ({sorted(counts)})")
        for name, width in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
            if name in values and values[name].shape[1] != width:
                raise AssetError(f"{label}: {name} must be VEC{width}, got {values[name].shape[1]} components")
        count = counts.pop()
        made += count
        if made > MAX_GLTF_INSTANCES:
            raise AssetError(f"{label}: the file's instances pass {MAX_GLTF_INSTANCES} "
                             "(engine.assets.gltf_instancing.MAX_GLTF_INSTANCES: each is an entity)")
        translation = values.get("TRANSLATION", np.zeros((count, 3), np.float32))
        rotation = values.get("ROTATION", np.tile(np.float32([0.0, 0.0, 0.0, 1.0]), (count, 1)))
        scale = values.get("SCALE", np.ones((count, 3), np.float32))
        mesh = node.pop("mesh")
        weights = node.pop("weights", None)   # (the node's morph weights are its mesh's: each instance's)
        del extensions["EXT_mesh_gpu_instancing"]
        first = len(nodes)
        for i in range(count):
            nodes.append({"mesh": mesh, "translation": translation[i].tolist(), "rotation": rotation[i].tolist(),
                          "scale": scale[i].tolist(), **({} if weights is None else {"weights": weights})})
        node["children"] = [*(node.get("children") or []), *range(first, first + count)]
        _weights_channels_to_instances(doc, index, range(first, first + count))
    return made


def _weights_channels_to_instances(doc: dict, index: int, instances: range) -> None:
    """A clip's ``weights`` channels on node ``index`` (its mesh's morph weights), played on
    each of its ``instances`` instead: one channel an instance, sharing the sampler."""
    for animation in doc.get("animations") or []:
        channels = animation.get("channels") if isinstance(animation, dict) else None
        if not isinstance(channels, list):
            continue
        kept = []
        for channel in channels:
            target = channel.get("target") if isinstance(channel, dict) else None
            if isinstance(target, dict) and target.get("node") == index and target.get("path") == "weights":
                kept += [{**channel, "target": {**target, "node": node}} for node in instances]
            else:
                kept.append(channel)
        animation["channels"] = kept
