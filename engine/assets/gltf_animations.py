"""glTF animations: a file's clips (``animations``: each channel a node's translation,
rotation or scale sampled at key times, with linear, step or cubic-spline interpolation),
read before trimesh parses the file (which ignores them), and the poses they give.

A model's parts are placed by their nodes (``ModelPart.node``); the node tree
(``NodeTree``: each node's parent and its own transform at rest) lets ``pose`` put every
part where a clip puts its node at a time: the animated nodes' sampled translation, rotation
and scale, the others at rest, multiplied down from the scene's roots.  ``Animation`` on a
model's root plays one (``systems/model_system.py``); a skinned part follows its joints' poses
(``engine/assets/gltf_skins.py``), and a ``weights`` channel sets the weights a node's mesh
wears its morph targets at (``engine/assets/gltf_morphs.py``; ``pose_weights``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from engine.assets.gltf_accessors import BufferBytes, read_float_accessor
from engine.assets.model_lights import node_matrix, placed_nodes
from engine.core.errors import AssetError

PATHS = {"translation": 3, "rotation": 4, "scale": 3}  # what a channel may animate, and its width
# ("weights" too: as wide as the node's mesh has morph targets)
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
MAX_KEYS = 1 << 20  # key times one channel may have


@dataclass
class Channel:
    """One node's translation, rotation (x, y, z, w), scale or morph weights over ``times``
    (seconds, increasing); ``values`` (keys, width), or (keys, 3, width) for a cubic spline:
    in-tangent, value, out-tangent."""

    node: int
    path: str
    times: np.ndarray
    values: np.ndarray
    interpolation: str

    def sample(self, t: float) -> np.ndarray:
        """The value at time ``t`` (held at the ends)."""
        times = self.times
        cubic = self.interpolation == "CUBICSPLINE"
        if t <= times[0] or len(times) == 1:
            value = self.values[0, 1] if cubic else self.values[0]
        elif t >= times[-1]:
            value = self.values[-1, 1] if cubic else self.values[-1]
        else:
            k = int(np.searchsorted(times, t, side="right")) - 1
            span = times[k + 1] - times[k]
            s = (t - times[k]) / span
            if self.interpolation == "STEP":
                value = self.values[k]
            elif cubic:  # glTF's Hermite spline: the tangents scaled by the span
                s2, s3 = s * s, s * s * s
                value = ((2 * s3 - 3 * s2 + 1) * self.values[k, 1] + (s3 - 2 * s2 + s) * span * self.values[k, 2]
                         + (-2 * s3 + 3 * s2) * self.values[k + 1, 1] + (s3 - s2) * span * self.values[k + 1, 0])
            elif self.path == "rotation":
                value = _slerp(self.values[k], self.values[k + 1], s)
            else:
                value = (1.0 - s) * self.values[k] + s * self.values[k + 1]
        if self.path == "rotation":
            length = float(np.linalg.norm(value))
            value = value / length if length > 0.0 else np.array([0.0, 0.0, 0.0, 1.0])
        return np.asarray(value, np.float64)


@dataclass
class Clip:
    """A file's animation: its ``name`` and channels; ``duration`` its last key's time."""

    name: str
    channels: list[Channel]
    duration: float


@dataclass
class NodeTree:
    """A glTF scene's nodes: each one's parent (None: a root) and its own transform at rest,
    as (translation, rotation x y z w, scale), or a matrix (``matrices``: nodes given one)."""

    parents: list[int | None] = field(default_factory=list)
    rest: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    matrices: dict[int, np.ndarray] = field(default_factory=dict)


def read_node_tree(doc: dict, what: str) -> NodeTree:
    """Every node's parent and rest transform; a node tree that is not one (a node reached
    twice, a child the file lacks) or a transform that is not finite numbers of the right
    count is an AssetError naming the node (``model_lights``' checks)."""
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    try:
        placed_nodes(doc, nodes)
        tree = NodeTree(parents=[None] * len(nodes))
        for index, node in enumerate(nodes):
            for child in (node.get("children") or []) if isinstance(node, dict) else []:
                tree.parents[child] = index
        for index, node in enumerate(nodes):
            node = node if isinstance(node, dict) else {}
            matrix = node_matrix(node, index)  # (checked)
            if "matrix" in node:
                tree.matrices[index] = matrix
            tree.rest.append((np.array(node.get("translation", [0.0, 0.0, 0.0]), np.float64),
                              np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), np.float64),
                              np.array(node.get("scale", [1.0, 1.0, 1.0]), np.float64)))
    except AssetError as exc:
        raise AssetError(f"{what}: {exc}") from None
    return tree


def read_animations(doc: dict, buffer_bytes: BufferBytes, what: str) -> list[Clip]:
    """The document's clips; a malformed one (a channel naming a node, sampler or accessor
    the file lacks, an unknown path or interpolation, key times that are not increasing
    finite numbers, values that do not match them, an animated node that has a matrix) is an
    AssetError naming the animation and channel."""
    animations = doc.get("animations")
    if animations is None:
        return []
    if not isinstance(animations, list):
        raise AssetError(f"{what}: animations must be a list, got {animations!r}")
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    clips: list[Clip] = []
    for a, animation in enumerate(animations):
        name = animation.get("name") if isinstance(animation, dict) else None
        label = f"{what}: animation {a}" + (f" ({name!r})" if isinstance(name, str) and name else "")
        if not isinstance(animation, dict):
            raise AssetError(f"{label}: must be an object, got {animation!r}")
        samplers = animation.get("samplers") if isinstance(animation.get("samplers"), list) else []
        listed = animation.get("channels", [])
        if not isinstance(listed, list):
            raise AssetError(f"{label}: channels must be a list, got {listed!r}")
        channels: list[Channel] = []
        for c, channel in enumerate(listed):
            where = f"{label}: channel {c}"
            target = channel.get("target") if isinstance(channel, dict) else None
            if not isinstance(target, dict):
                raise AssetError(f"{where}: needs a target object, got {channel!r}")
            path = target.get("path")
            if path not in PATHS and path != "weights":
                raise AssetError(f"{where}: target.path must be one of {sorted(PATHS)} or 'weights', got {path!r}")
            node = target.get("node")
            if isinstance(node, bool) or not isinstance(node, int) or not 0 <= node < len(nodes):
                raise AssetError(f"{where}: target.node names node {node!r}, which the file does not have")
            width = PATHS.get(path, 0)
            if path == "weights":
                width = _target_count(nodes[node], meshes)
                if not width:
                    raise AssetError(f"{where}: animates the morph weights of node {node}, whose mesh has no morph "
                                     "targets")
            elif isinstance(nodes[node], dict) and "matrix" in nodes[node]:
                raise AssetError(f"{where}: animates node {node}, which has a matrix (glTF animates only "
                                 "translation, rotation and scale nodes)")
            s = channel.get("sampler")
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < len(samplers) \
                    or not isinstance(samplers[s], dict):
                raise AssetError(f"{where}: names sampler {s!r}, which the animation does not have")
            channels.append(_channel(samplers[s], node, path, width, buffer_bytes, doc, f"{where}: sampler {s}"))
        duration = max((float(ch.times[-1]) for ch in channels), default=0.0)
        clips.append(Clip(name if isinstance(name, str) and name else f"animation {a}", channels, duration))
    return clips


def _target_count(node: object, meshes: list) -> int:
    """How many morph targets the mesh of ``node`` has (0: none, or no mesh)."""
    mesh = node.get("mesh") if isinstance(node, dict) else None
    if isinstance(mesh, bool) or not isinstance(mesh, int) or not 0 <= mesh < len(meshes) \
            or not isinstance(meshes[mesh], dict):
        return 0
    primitives = meshes[mesh].get("primitives") or []
    first = primitives[0] if isinstance(primitives, list) and primitives and isinstance(primitives[0], dict) else {}
    targets = first.get("targets") or []
    return len(targets) if isinstance(targets, list) else 0


def _channel(sampler: dict, node: int, path: str, width: int, buffer_bytes: BufferBytes, doc: dict,
             where: str) -> Channel:
    interpolation = sampler.get("interpolation", "LINEAR")
    if interpolation not in INTERPOLATIONS:
        raise AssetError(f"{where}: interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    times = read_float_accessor(doc, sampler.get("input"), buffer_bytes, f"{where}: input").reshape(-1)
    values = read_float_accessor(doc, sampler.get("output"), buffer_bytes, f"{where}: output")
    if path == "weights" and values.ndim == 2 and values.shape[1] == 1:  # (scalars: a key's weights in a row)
        values = values.reshape(-1, width) if len(values) % width == 0 else values
    if len(times) == 0 or len(times) > MAX_KEYS:
        raise AssetError(f"{where}: has {len(times)} key times (1 to {MAX_KEYS})")
    if not np.isfinite(times).all() or (np.diff(times) <= 0.0).any():
        raise AssetError(f"{where}: its key times must be finite and increasing")
    per_key = 3 if interpolation == "CUBICSPLINE" else 1
    if values.ndim != 2 or values.shape != (len(times) * per_key, width) or not np.isfinite(values).all():
        raise AssetError(f"{where}: its output must be {len(times) * per_key} finite {path} values of {width} "
                         f"({len(times)} keys{' x 3 for a cubic spline' if per_key == 3 else ''}), "
                         f"got shape {values.shape}")
    values = values.astype(np.float64)
    if per_key == 3:
        values = values.reshape(len(times), 3, width)
    return Channel(node, path, times.astype(np.float64), values, interpolation)


def _slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation of unit quaternions (x, y, z, w) along the shorter arc."""
    d = float(np.dot(a, b))
    if d < 0.0:
        b, d = -b, -d
    if d > 0.9995:
        return (1.0 - s) * a + s * b
    angle = math.acos(min(d, 1.0))
    return (math.sin((1.0 - s) * angle) * a + math.sin(s * angle) * b) / math.sin(angle)


def trs_matrix(translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """T x R x S as a 4 x 4 float64 matrix; rotation (x, y, z, w), unit."""
    x, y, z, w = rotation
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * scale
    m[:3, 3] = translation
    return m


def pose_weights(clip: Clip, t: float) -> dict[int, np.ndarray]:
    """The morph weights at time ``t`` of each node a ``weights`` channel of ``clip`` animates."""
    return {channel.node: channel.sample(t) for channel in clip.channels if channel.path == "weights"}


def moved_nodes(tree: NodeTree, clip: Clip) -> set[int]:
    """The nodes ``clip`` moves: those it animates (their transform) and every node under them."""
    animated = {channel.node for channel in clip.channels if channel.path != "weights"}
    moved = set()
    for node in range(len(tree.parents)):
        walk: int | None = node
        while walk is not None and walk not in animated:
            walk = tree.parents[walk]
        if walk is not None:
            moved.add(node)
    return moved


def pose(tree: NodeTree, clip: Clip, t: float, wanted: list[int]) -> dict[int, np.ndarray]:
    """The model-space matrix at time ``t`` of each node in ``wanted`` (and of their
    ancestors): its own transform (the clip's channels where it animates it, else at rest)
    times its parent's."""
    animated: dict[int, dict[str, np.ndarray]] = {}
    for channel in clip.channels:
        if channel.path == "weights":
            continue  # (pose_weights: no transform)
        animated.setdefault(channel.node, {})[channel.path] = channel.sample(t)
    placed: dict[int, np.ndarray] = {}

    def matrix(node: int) -> np.ndarray:
        found = placed.get(node)
        if found is None:
            if node in tree.matrices:
                local = tree.matrices[node]
            else:
                rest_t, rest_r, rest_s = tree.rest[node]
                own = animated.get(node, {})
                local = trs_matrix(own.get("translation", rest_t), own.get("rotation", rest_r),
                                   own.get("scale", rest_s))
            parent = tree.parents[node]
            found = placed[node] = local if parent is None else matrix(parent) @ local
        return found

    for node in wanted:
        matrix(node)
    return placed
