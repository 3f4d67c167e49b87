"""The cameras a glTF file carries (core glTF's ``cameras``, named by nodes), read from its
JSON and placed by its node tree, for ``spawn_model`` to make into the engine's cameras.

Blender writes a scene's cameras this way (a turntable's, a level's cut-scene shots), and
three.js's, Godot's and Babylon.js's loaders bring them in; a game switches to one by
making it active.  A glTF camera looks along its node's -Z with +Y up, as the engine's do.
A perspective camera's ``yfov`` (radians) is the engine's ``Camera.fov_y`` (degrees),
``znear`` its near plane and ``zfar`` its far one (none given: an infinite projection in
glTF, the engine's default far here, the engine's cameras having a far plane); its
``aspectRatio`` is left to the picture's (glTF: "when undefined, the aspect ratio of the
rendering viewport"; the engine's cameras always take the picture's).  An orthographic
camera's ``ymag`` (half its height) makes ``Camera.ortho_height`` (its ``xmag`` left to the
picture's aspect, as ``aspectRatio`` is), its ``znear`` and ``zfar`` its planes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pyglm import glm

from engine.assets.model_lights import finite_number, placed_nodes
from engine.core.errors import AssetError


@dataclass
class ModelCamera:
    """One perspective camera of a model file, where its node puts it: ``local`` its node's
    transform in the model (as ``ModelPart.local``), ``fov_y`` in degrees, ``near`` and
    ``far`` (None: none given) in the model's units."""

    fov_y: float
    near: float
    far: float | None
    local: glm.mat4
    name: str
    node: int | None = None  # its node's index (what an animation moves)
    ortho_height: float | None = None  # an orthographic camera's height (2 x ymag; None: perspective)
    camera: int | None = None  # its index in the file's cameras (what an animation pointer names)


def read_gltf_cameras(doc: dict | None) -> list[ModelCamera]:
    """The cameras the nodes of a glTF document's scene name, each placed by its node and
    ancestors (a camera named by two nodes is two cameras).  A malformed camera (a field that
    is not a finite number, ``yfov`` outside the engine's 1-179 degrees, ``ymag`` not above 0,
    ``znear`` not above 0 (perspective) or below 0 (orthographic) or ``zfar`` not beyond it,
    an index the file does not have) is an AssetError naming it."""
    if not isinstance(doc, dict):
        return []
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    if not any(isinstance(node, dict) and "camera" in node for node in nodes):
        return []
    defined = doc.get("cameras")
    if not isinstance(defined, list):
        raise AssetError("a node names a camera, but the file defines none (cameras)")
    found: list[ModelCamera] = []
    for index, matrix in placed_nodes(doc, nodes):
        if "camera" not in nodes[index]:
            continue
        which = nodes[index]["camera"]
        if isinstance(which, bool) or not isinstance(which, int) or not 0 <= which < len(defined):
            raise AssetError(f"node {index} names camera {which!r}, which the file does not have "
                             f"({len(defined)} defined)")
        camera = _camera(defined, which)
        camera.local = glm.mat4(*matrix.astype(np.float32).T.ravel())
        camera.node = index
        camera.camera = which
        found.append(camera)
    return found


def _name(entry: object, index: int) -> str:
    name = entry.get("name") if isinstance(entry, dict) else None
    return name if isinstance(name, str) and name else f"camera {index}"


def _camera(defined: list, index: int) -> ModelCamera:
    """Camera ``index`` of the file's ``cameras``, checked (placed at the origin)."""
    entry = defined[index]
    name = _name(entry, index)
    what = f"camera {index}" + (f" ({name!r})" if name != f"camera {index}" else "")
    if not isinstance(entry, dict):
        raise AssetError(f"{what}: must be an object, got {entry!r}")
    kind = entry.get("type")
    if kind == "orthographic" and isinstance(entry.get("orthographic"), dict):
        return _orthographic(entry["orthographic"], what, name)
    if kind != "perspective" or not isinstance(entry.get("perspective"), dict):
        raise AssetError(f"{what}: type must be 'perspective' (with its perspective object) or 'orthographic', "
                         f"got {kind!r}")
    perspective = entry["perspective"]
    yfov, znear, zfar = perspective.get("yfov"), perspective.get("znear"), perspective.get("zfar")
    if not (finite_number(yfov) and 1.0 <= math.degrees(yfov) <= 179.0):
        raise AssetError(f"{what}: yfov must be an angle in radians between 1 and 179 degrees (the engine's "
                         f"Camera.fov_y), got {yfov!r}")
    if not (finite_number(znear) and znear > 0.0):
        raise AssetError(f"{what}: znear must be a number > 0, got {znear!r}")
    if zfar is not None and not (finite_number(zfar) and zfar > znear):
        raise AssetError(f"{what}: zfar must be a number beyond znear ({znear!r}), got {zfar!r}")
    return ModelCamera(math.degrees(yfov), float(znear), None if zfar is None else float(zfar), glm.mat4(), name)


def _orthographic(lens: dict, what: str, name: str) -> ModelCamera:
    """An orthographic camera's lens, checked: ``ymag`` half its height, ``znear`` >= 0 and
    ``zfar`` beyond it (both required by glTF); the engine's near plane is held just above 0."""
    ymag, znear, zfar = lens.get("ymag"), lens.get("znear"), lens.get("zfar")
    if not (finite_number(ymag) and 0.0 < ymag <= 5e5):
        raise AssetError(f"{what}: ymag must be a number > 0 (half the view's height, at most 500000), got {ymag!r}")
    if not (finite_number(znear) and znear >= 0.0):
        raise AssetError(f"{what}: znear must be a number >= 0, got {znear!r}")
    if not (finite_number(zfar) and zfar > znear):
        raise AssetError(f"{what}: zfar must be a number beyond znear ({znear!r}), got {zfar!r}")
    return ModelCamera(60.0, max(float(znear), 1e-3), float(zfar), glm.mat4(), name, ortho_height=2.0 * float(ymag))
