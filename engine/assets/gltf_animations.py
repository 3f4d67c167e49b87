"""glTF animations: a file's clips (``animations``: each channel a node's translation,
rotation or scale sampled at key times, with linear, step or cubic-spline interpolation),
read before trimesh parses the file (which ignores them), and the poses they give.

``KHR_animation_pointer`` (Blender 4.2 and later export it) names a channel's target by a
JSON pointer: a node's ``/nodes/{i}/translation``, ``rotation``, ``scale`` or ``weights`` is
read as that node's channel; a material's ``baseColorFactor``, ``metallicFactor``,
``roughnessFactor``, ``alphaCutoff``, ``emissiveFactor`` and ``KHR_materials_emissive_strength``,
its normal texture's ``scale`` and occlusion texture's ``strength``, a ``KHR_lights_punctual``
light's ``color``, ``intensity``, ``range`` and spot cone angles, and a camera's ``yfov``
(perspective), ``ymag`` (orthographic), ``znear`` and ``zfar`` are the clip's
``properties`` (``PROPERTY_POINTERS``), which the models stage writes into the components made
from them (``engine/assets/models.py``); any other pointer is left out with a warning naming
it, and the clip plays the rest.

A model's parts are placed by their nodes (``ModelPart.node``); the node tree
(``NodeTree``: each node's parent and its own transform at rest) lets ``pose_all`` put every
part where a clip puts its node at a time: the animated nodes' sampled translation, rotation
and scale, the others at rest, multiplied down from the scene's roots.  ``Animation`` on a
model's root plays one (``systems/model_system.py``); a skinned part follows its joints' poses
(``engine/assets/gltf_skins.py``), and a ``weights`` channel sets the weights a node's mesh
wears its morph targets at (``engine/assets/gltf_morphs.py``; ``pose_weights``).
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from engine.assets.gltf_accessors import BufferBytes, read_float_accessor
from engine.assets.model_lights import node_matrix, placed_nodes
from engine.core.errors import AssetError

PATHS = {"translation": 3, "rotation": 4, "scale": 3}  # what a channel may animate, and its width
# ("weights" too: as wide as the node's mesh has morph targets)
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
MAX_KEYS = 1 << 20  # key times one channel may have
POINTER = "KHR_animation_pointer"
_INDEX = r"(0|[1-9][0-9]*)"
_NODE_POINTER = re.compile(rf"/nodes/{_INDEX}/(translation|rotation|scale|weights)")
# The properties a pointer may animate besides nodes: (pattern, what it names: the document's
# array of them, its width, the channel's name: None for the pattern's second group)
PROPERTY_POINTERS = (
    (re.compile(rf"/materials/{_INDEX}/pbrMetallicRoughness/(baseColorFactor)"), "materials", 4, None),
    (re.compile(rf"/materials/{_INDEX}/pbrMetallicRoughness/(metallicFactor|roughnessFactor)"), "materials", 1, None),
    (re.compile(rf"/materials/{_INDEX}/(alphaCutoff)"), "materials", 1, None),
    (re.compile(rf"/materials/{_INDEX}/(emissiveFactor)"), "materials", 3, None),
    (re.compile(rf"/materials/{_INDEX}/extensions/KHR_materials_emissive_strength/(emissiveStrength)"),
     "materials", 1, None),
    (re.compile(rf"/materials/{_INDEX}/normalTexture/(scale)"), "materials", 1, "normalScale"),
    (re.compile(rf"/materials/{_INDEX}/occlusionTexture/(strength)"), "materials", 1, "occlusionStrength"),
    (re.compile(rf"/extensions/KHR_lights_punctual/lights/{_INDEX}/(color)"), "lights", 3, None),
    (re.compile(rf"/extensions/KHR_lights_punctual/lights/{_INDEX}/(intensity|range)"), "lights", 1, None),
    (re.compile(rf"/extensions/KHR_lights_punctual/lights/{_INDEX}/spot/(innerConeAngle|outerConeAngle)"),
     "lights", 1, None),
    (re.compile(rf"/cameras/{_INDEX}/perspective/(yfov|znear|zfar)"), "cameras", 1, None),
    (re.compile(rf"/cameras/{_INDEX}/orthographic/(ymag|znear|zfar)"), "cameras", 1, None),
)


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


@dataclass
class Clip:
    """A file's animation: its ``name`` and channels; ``duration`` its last key's time.
    ``properties``: its ``KHR_animation_pointer`` channels of materials, lights and cameras,
    each a ``Channel`` whose ``node`` is the material's, light's or camera's index and whose
    ``path`` is "materials.baseColorFactor", "lights.intensity", "cameras.yfov"..."""

    name: str
    channels: list[Channel]
    duration: float
    properties: list[Channel] = field(default_factory=list)
    # Its channels grouped for sampling on arrays (``_groups``), made at its first pose.
    groups: list | None = field(default=None, repr=False, compare=False)


@dataclass
class NodeTree:
    """A glTF scene's nodes: each one's parent (None: a root) and its own transform at rest,
    as (translation, rotation x y z w, scale), or a matrix (``matrices``: nodes given one)."""

    parents: list[int | None] = field(default_factory=list)
    rest: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    matrices: dict[int, np.ndarray] = field(default_factory=dict)
    names: list[str | None] = field(default_factory=list)  # each node's name in the file (None: none)
    # The same as arrays, and the nodes by depth, made at the first pose (``_tree_arrays``).
    arrays: tuple | None = field(default=None, repr=False, compare=False)


def read_node_tree(doc: dict, what: str) -> NodeTree:
    """Every node's parent and rest transform; a node tree that is not one (a node reached
    twice, a child the file lacks) or a transform that is not finite numbers of the right
    count is an AssetError naming the node (``model_lights``' checks)."""
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    try:
        placed_nodes(doc, nodes)
        tree = NodeTree(parents=[None] * len(nodes),
                        names=[n.get("name") if isinstance(n, dict) and isinstance(n.get("name"), str) else None
                               for n in nodes])
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
        properties: list[Channel] = []
        for c, channel in enumerate(listed):
            where = f"{label}: channel {c}"
            target = channel.get("target") if isinstance(channel, dict) else None
            if not isinstance(target, dict):
                raise AssetError(f"{where}: needs a target object, got {channel!r}")
            path = target.get("path")
            node = target.get("node")
            if path == "pointer":
                found = _pointed(target, doc, where)
                if found is None:
                    continue
                node, path, width = found
                if "." in path:  # a material's, light's or camera's property
                    s = channel.get("sampler")
                    if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < len(samplers) \
                            or not isinstance(samplers[s], dict):
                        raise AssetError(f"{where}: names sampler {s!r}, which the animation does not have")
                    made = _channel(samplers[s], node, path, width, buffer_bytes, doc, f"{where}: sampler {s}")
                    _check_property(made, where)
                    properties.append(made)
                    continue
            if path not in PATHS and path != "weights":  # (a pointer's node path is one of them)
                raise AssetError(f"{where}: target.path must be one of {sorted(PATHS)}, 'weights' or 'pointer' "
                                 f"(KHR_animation_pointer), got {path!r}")
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
        duration = max((float(ch.times[-1]) for ch in (*channels, *properties)), default=0.0)
        clips.append(Clip(name if isinstance(name, str) and name else f"animation {a}", channels, duration,
                          properties))
    return clips


def _pointed(target: dict, doc: dict, where: str) -> tuple[int, str, int] | None:
    """A ``KHR_animation_pointer`` target as (index, path, width): a node's translation,
    rotation, scale or weights as its node channel (the width worked out as for ``path``), a
    property of ``PROPERTY_POINTERS`` as (its material's, light's or camera's index, "kind.name",
    its width); None (warned: left out) for any other pointer.  An AssetError where the target
    has no pointer string, or a property's index names what the file does not have."""
    extension = (target.get("extensions") or {}).get(POINTER) if isinstance(target.get("extensions"), dict) else None
    pointer = extension.get("pointer") if isinstance(extension, dict) else None
    if not isinstance(pointer, str):
        raise AssetError(f"{where}: target.path 'pointer' needs extensions.{POINTER}.pointer, a string, got "
                         f"{pointer!r}")
    match = _NODE_POINTER.fullmatch(pointer)
    if match is not None:
        return int(match.group(1)), match.group(2), 0
    for pattern, kind, width, name in PROPERTY_POINTERS:
        match = pattern.fullmatch(pointer)
        if match is None:
            continue
        index = int(match.group(1))
        listed = ((doc.get("extensions") or {}).get("KHR_lights_punctual") or {}).get("lights") \
            if kind == "lights" else doc.get(kind)
        if not isinstance(listed, list) or index >= len(listed):
            raise AssetError(f"{where}: {POINTER} {pointer!r} names {kind[:-1]} {index}, which the file does not have")
        return index, f"{kind}.{name or match.group(2)}", width
    warnings.warn(f"{where}: {POINTER} {pointer!r} left out (a node's transform and weights, a material's "
                  "colour, metallic, roughness, cutoff, emission and its strength, normal scale and occlusion "
                  "strength, a light's colour, intensity, range and spot cones and a camera's field of view, "
                  "height and clip planes are played); the clip plays the rest", stacklevel=6)
    return None


# Each property's keys must lie in [low, high] (what the engine's field takes; a cubic
# spline's overshoot between keys is kept inside when written).
PROPERTY_RANGES = {"baseColorFactor": (0.0, None), "metallicFactor": (0.0, 1.0), "roughnessFactor": (0.0, 1.0),
                   "alphaCutoff": (0.0, 1.0), "emissiveFactor": (0.0, None), "emissiveStrength": (0.0, None),
                   "normalScale": (0.0, None), "occlusionStrength": (0.0, 1.0),
                   "color": (0.0, None), "intensity": (0.0, None), "range": (1e-6, None),
                   "innerConeAngle": (0.0, np.pi / 2), "outerConeAngle": (1e-6, np.pi / 2),
                   "yfov": (np.radians(1.0), np.radians(179.0)), "ymag": (1e-6, 5e5),
                   "znear": (0.0, None), "zfar": (1e-6, None)}


def _check_property(channel: Channel, where: str) -> None:
    """An AssetError naming the channel where a key's value is outside what its property takes."""
    name = channel.path.split(".")[1]
    low, high = PROPERTY_RANGES[name]
    keys = channel.values[:, 1] if channel.values.ndim == 3 else channel.values
    if (keys < low).any() or (high is not None and (keys > high).any()) \
            or (name == "baseColorFactor" and (keys[:, 3] > 1.0).any()):
        raise AssetError(f"{where}: {channel.path} keys must lie in [{low:g}, {'inf' if high is None else f'{high:g}'}]"
                         f"{' (alpha at most 1)' if name == 'baseColorFactor' else ''}, got {keys.min():g} to "
                         f"{keys.max():g}")


def sample_property(channel: Channel, t: float) -> np.ndarray:
    """A property channel's value at ``t`` (seconds; held at its first and last keys): its
    keys mixed linearly, stepped, or along its cubic spline (Hermite, the tangents scaled by the
    keys' gap), as glTF defines them."""
    times = channel.times
    if t <= times[0] or len(times) == 1:
        k, s = 0, 0.0
    elif t >= times[-1]:
        k, s = len(times) - 1, 0.0
    else:
        k = int(np.searchsorted(times, t, side="right")) - 1
        s = (t - times[k]) / (times[k + 1] - times[k])
    values = channel.values
    if channel.interpolation == "CUBICSPLINE":
        if s == 0.0:
            return values[k, 1].copy()
        gap = times[k + 1] - times[k]
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * values[k, 1] + (s3 - 2 * s2 + s) * gap * values[k, 2]
                + (-2 * s3 + 3 * s2) * values[k + 1, 1] + (s3 - s2) * gap * values[k + 1, 0])
    if channel.interpolation == "STEP" or s == 0.0:
        return values[k].copy()
    return values[k] * (1.0 - s) + values[k + 1] * s


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


def collapsed(matrix: np.ndarray) -> bool:
    """Whether a transform (4 x 4, or its 3 x 3) squashes everything flat or to a point (a
    scale of 0 on some axis: how files hide a node, and how clips make one vanish or grow)."""
    singular = np.linalg.svd(np.asarray(matrix, np.float64)[:3, :3], compute_uv=False)
    return bool(singular[-1] <= 1e-9 * singular[0] or singular[0] == 0.0)


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


@dataclass(frozen=True)
class Layer:
    """An ``AnimationLayer`` as ``pose_all`` lays it over the base pose: its clip at ``time``,
    its ``weight``, whether it adds (``additive``) or overrides, and the nodes it may act on
    (``nodes``: a mask a node, ``subtree``'s; None: all)."""

    clip: Clip
    time: float
    weight: float
    additive: bool = False
    nodes: np.ndarray | None = None


def subtree(tree: NodeTree, root: int) -> np.ndarray:
    """A mask of ``root`` and every node under it (bool, a node each)."""
    inside = np.zeros(len(tree.parents), bool)
    for node in range(len(tree.parents)):
        walk: int | None = node
        while walk is not None and walk != root:
            walk = tree.parents[walk]
        inside[node] = walk == root
    return inside


def pose_all(tree: NodeTree, clip: Clip, t: float, fade: tuple[Clip, float, float] | None = None,
             layer: Layer | None = None) -> np.ndarray:
    """Every node's model-space matrix at time ``t`` (N, 4, 4): its own transform (the clip's
    channels where it animates it, else at rest) times its parent's, on arrays: each group
    of channels sampled at once (``_sample``), every node's T x R x S made at once, and the
    tree multiplied down a depth at a time (a 60-joint character's pose is a few dozen
    numpy calls, not one chain of them a node).  A node outside the scene's tree is its own
    transform.  ``fade``: (the clip faded from, its time, ``clip``'s share from 0 to 1): each
    node's own transforms from the two mixed (translation and scale linearly, rotation along
    the shorter arc) before they are multiplied down.  ``layer``: a second clip laid over
    that pose (``_layered``)."""
    with_matrix, matrices, levels = _tree_arrays(tree)[3:]
    translation, rotation, scale = _own_transforms(tree, clip, t)
    if fade is not None:
        old_clip, old_time, share = fade
        old_t, old_r, old_s = _own_transforms(tree, old_clip, old_time)
        translation = old_t + share * (translation - old_t)
        scale = old_s + share * (scale - old_s)
        rotation = _slerp_rows(old_r, rotation, share)
        rotation /= np.linalg.norm(rotation, axis=1, keepdims=True)
    if layer is not None:
        translation, rotation, scale = _layered(tree, translation, rotation, scale, layer)
    local = trs_matrices(translation, rotation, scale)
    if len(with_matrix):
        local[with_matrix] = matrices
    placed = local.copy()
    for nodes, parents in levels:
        if isinstance(nodes, int):  # one node this deep (a chain): plain indexing, no gather
            np.matmul(placed[parents], local[nodes], out=placed[nodes])
        else:
            placed[nodes] = placed[parents] @ local[nodes]
    return placed


def _own_transforms(tree: NodeTree, clip: Clip, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every node's own translation, rotation and scale at time ``t`` of ``clip`` (at rest
    where it animates none)."""
    rest_t, rest_r, rest_s = _tree_arrays(tree)[:3]
    own = {"translation": rest_t.copy(), "rotation": rest_r.copy(), "scale": rest_s.copy()}
    for group in _groups(clip):
        if group.path != "weights":
            own[group.path][group.nodes] = _sample(group, t)
    return own["translation"], own["rotation"], own["scale"]


def _layered(tree: NodeTree, translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray,
             layer: Layer) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The base pose's own transforms with ``layer`` laid over them, on the nodes and paths
    its clip animates (within its mask): overriding, each moved towards the layer's by its
    weight (translation and scale linearly, rotation along the shorter arc); adding, the
    layer's change from its clip's first key (sampled at time 0: each channel's first value)
    times the weight added on (translation and scale: the difference; rotation: the turn
    from the first key's, taken ``weight`` of the way and applied after the base's)."""
    own = _own_transforms(tree, layer.clip, layer.time)
    first = _own_transforms(tree, layer.clip, 0.0) if layer.additive else None
    result = [translation.copy(), rotation.copy(), scale.copy()]
    w = layer.weight
    for group in _groups(layer.clip):
        if group.path == "weights":
            continue
        nodes = group.nodes if layer.nodes is None else group.nodes[layer.nodes[group.nodes]]
        if not len(nodes):
            continue
        k = ("translation", "rotation", "scale").index(group.path)
        base, theirs = result[k][nodes], own[k][nodes]
        if k == 1:
            if layer.additive:
                turn = _quaternion_product(first[1][nodes] * (-1.0, -1.0, -1.0, 1.0), theirs)  # first^-1 x layer
                turned = _slerp_rows(np.tile((0.0, 0.0, 0.0, 1.0), (len(nodes), 1)), turn, w)
                moved = _quaternion_product(base, turned)
            else:
                moved = _slerp_rows(base, theirs, w)
            result[k][nodes] = moved / np.linalg.norm(moved, axis=1, keepdims=True)
        else:
            result[k][nodes] = base + w * (theirs - (first[k][nodes] if layer.additive else base))
    return result[0], result[1], result[2]


def layer_weights(layer: Layer) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray] | None]:
    """``layer``'s clip's morph weights at its time and, adding, at its first key (None:
    overriding), each node's: sampled once a pose for ``layered_weights``."""
    return pose_weights(layer.clip, layer.time), pose_weights(layer.clip, 0.0) if layer.additive else None


def layered_weights(base: np.ndarray | None, rest: np.ndarray, node: int, layer: Layer,
                    sampled: tuple[dict[int, np.ndarray], dict[int, np.ndarray] | None]) -> np.ndarray | None:
    """Node ``node``'s morph weights with ``layer`` (``sampled``: its ``layer_weights``) over
    ``base`` (None: its ``rest``, the file's), where its clip animates them within its mask
    (else ``base`` as it is)."""
    if layer.nodes is not None and not layer.nodes[node]:
        return base
    theirs = sampled[0].get(node)
    if theirs is None:
        return base
    under = rest if base is None else base
    if layer.additive:
        return under + layer.weight * (theirs - sampled[1][node])
    return under + layer.weight * (theirs - under)


def _quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for each row pair of quaternions (x, y, z, w): b's turn, then a's."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=1)


def pose_weights(clip: Clip, t: float) -> dict[int, np.ndarray]:
    """The morph weights at time ``t`` of each node a ``weights`` channel of ``clip`` animates."""
    found: dict[int, np.ndarray] = {}
    for group in _groups(clip):
        if group.path == "weights":
            found.update(zip(group.nodes.tolist(), _sample(group, t), strict=True))
    return found


def trs_matrices(translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """T x R x S for each row (N, 4, 4, float64); rotations (x, y, z, w), unit."""
    x, y, z, w = rotation.T
    r = np.empty((len(rotation), 3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    r[:, 1, 0], r[:, 1, 1], r[:, 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    r[:, 2, 0], r[:, 2, 1], r[:, 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    m = np.zeros((len(rotation), 4, 4))
    m[:, :3, :3] = r * scale[:, None, :]
    m[:, :3, 3] = translation
    m[:, 3, 3] = 1.0
    return m


@dataclass
class _Group:
    """Channels of one path and interpolation sharing their key times (exporters bake a clip's
    channels at the same frames): sampled together."""

    path: str
    interpolation: str
    times: np.ndarray
    nodes: np.ndarray   # (C,)
    values: np.ndarray  # (C, keys, width), or (C, keys, 3, width) for a cubic spline


def _groups(clip: Clip) -> list[_Group]:
    """``clip``'s channels grouped (made once a clip)."""
    if clip.groups is None:
        grouped: dict[tuple, list[Channel]] = {}
        for channel in clip.channels:
            key = (channel.path, channel.interpolation, channel.values.shape[1:], channel.times.tobytes())
            grouped.setdefault(key, []).append(channel)
        clip.groups = [_Group(channels[0].path, channels[0].interpolation, channels[0].times,
                              np.array([c.node for c in channels], np.int64),
                              np.stack([c.values for c in channels])) for channels in grouped.values()]
    return clip.groups


def _sample(group: _Group, t: float) -> np.ndarray:
    """Each of the group's channels at time ``t`` (C, width), held at the ends."""
    times, values = group.times, group.values
    cubic = group.interpolation == "CUBICSPLINE"
    if t <= times[0] or len(times) == 1:
        value = values[:, 0, 1] if cubic else values[:, 0]
    elif t >= times[-1]:
        value = values[:, -1, 1] if cubic else values[:, -1]
    else:
        k = int(np.searchsorted(times, t, side="right")) - 1
        span = times[k + 1] - times[k]
        s = (t - times[k]) / span
        if group.interpolation == "STEP":
            value = values[:, k]
        elif cubic:  # glTF's Hermite spline: the tangents scaled by the span
            s2, s3 = s * s, s * s * s
            value = ((2 * s3 - 3 * s2 + 1) * values[:, k, 1] + (s3 - 2 * s2 + s) * span * values[:, k, 2]
                     + (-2 * s3 + 3 * s2) * values[:, k + 1, 1] + (s3 - s2) * span * values[:, k + 1, 0])
        elif group.path == "rotation":
            value = _slerp_rows(values[:, k], values[:, k + 1], s)
        else:
            value = (1.0 - s) * values[:, k] + s * values[:, k + 1]
    if group.path == "rotation":
        length = np.linalg.norm(value, axis=1, keepdims=True)
        value = np.where(length > 0.0, value / np.where(length > 0.0, length, 1.0), (0.0, 0.0, 0.0, 1.0))
    return np.asarray(value, np.float64)


def _slerp_rows(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation of each row pair of unit quaternions (x, y, z, w): along the
    shorter arc, a lerp where they nearly agree."""
    d = np.einsum("ij,ij->i", a, b)
    b = np.where(d[:, None] < 0.0, -b, b)
    d = np.abs(d)
    angle = np.arccos(np.minimum(d, 1.0))
    sine = np.sin(angle)
    near = d > 0.9995
    safe = np.where(near, 1.0, sine)
    wa = np.where(near, 1.0 - s, np.sin((1.0 - s) * angle) / safe)
    wb = np.where(near, s, np.sin(s * angle) / safe)
    return wa[:, None] * a + wb[:, None] * b


def _tree_arrays(tree: NodeTree) -> tuple:
    """The tree's rest transforms as arrays, its matrix nodes, and its nodes by depth below
    the roots as (nodes, their parents) index arrays, or a (node, parent) pair where one node
    is that deep (made once a tree)."""
    if tree.arrays is None:
        count = len(tree.parents)
        rest_t = np.array([r[0] for r in tree.rest], np.float64).reshape(count, 3)
        rest_r = np.array([r[1] for r in tree.rest], np.float64).reshape(count, 4)
        rest_s = np.array([r[2] for r in tree.rest], np.float64).reshape(count, 3)
        with_matrix = np.array(sorted(tree.matrices), np.int64)
        matrices = np.array([tree.matrices[n] for n in with_matrix.tolist()], np.float64).reshape(-1, 4, 4)
        children: dict[int, list[int]] = {}
        for node, parent in enumerate(tree.parents):
            if parent is not None:
                children.setdefault(parent, []).append(node)
        levels = []
        frontier = [node for node, parent in enumerate(tree.parents) if parent is None]
        seen = set(frontier)
        while frontier:
            below = [(child, parent) for parent in frontier for child in children.get(parent, ()) if child not in seen]
            seen.update(child for child, _ in below)
            if len(below) == 1:
                levels.append(below[0])
            elif below:
                levels.append((np.array([c for c, _ in below], np.int64), np.array([p for _, p in below], np.int64)))
            frontier = [c for c, _ in below]
        tree.arrays = (rest_t, rest_r, rest_s, with_matrix, matrices, levels)
    return tree.arrays
