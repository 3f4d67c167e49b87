"""A mesh's pose: the matrices its joints bend it by (``Skin``) and how much of each of its
morph targets it wears (``Morph``).

A mesh with joints and weights a vertex (``Mesh.joints``, ``Mesh.weights``: a character's
body, a rope, a flag) is bent by the ``Skin`` on its entity: ``joint_matrices`` holds one
4 x 4 matrix a joint (numpy, (J, 4, 4), points as columns: ``M @ (x, y, z, 1)``), each the
joint's pose times its inverse bind matrix, in the mesh's own space (the identity: the joint
where the mesh was modelled).  The GPU blends each vertex's joints by its weights in every
view and shadow map (``shaders/include/pose.glsl``; ``engine/core/skinning.py`` the same
sum on arrays).  A model file's skinned parts get theirs from the file, posed by their
``Animation`` each frame (``systems/model_system.py``); a game may give its own.

``skinning`` says how a vertex's joints blend: "linear" (the default: their matrices summed
by weight, as glTF viewers, three.js, Unity and Godot draw skins) or "dual_quaternion"
(Blender's "Preserve Volume", Maya's and Unreal's dual quaternion skinning: their rotations
and translations blended as unit dual quaternions, their scales by weight), which keeps a
twisted wrist or a bent elbow its thickness where linear blending pinches it (the
"candy-wrapper"); a joint's stretch (its scale and shear, uneven or not) blends by weight
apart from its turn, before it (Kavan et al.'s two-phase blend), so a joint squashed and
stretched bends its vertices as its matrix does.

Assign a new array to pose it (``skin.joint_matrices = posed``): an array edited in place is
not seen until ``skin.touch()``.  At most ``MAX_JOINTS`` joints; the mesh's highest joint
must have a matrix (checked when either is given: ``engine/rules/pose_rules.py``).

A mesh with morph targets (``Mesh.morph_positions``: glTF's ``targets``, blend shapes: a
face's smile, a flag's ripple) wears them by the ``Morph`` on its entity: one weight a
target, each target's offsets times its weight added to the mesh as modelled, before any
Skin bends it.  A model file's morphed parts get the file's weights, played by a clip's
``weights`` channels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from components.limits import MAX_JOINTS, MAX_MORPH_TARGETS, MAX_MORPH_WEIGHT
from components.tracking import ComponentValueError, TrackedComponent, choice

MAX_JOINT_VALUE = 1e18  # a matrix entry past this leaves float32 once multiplied out
SKINNING_METHODS = ("linear", "dual_quaternion")  # Skin.skinning's
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0], np.float32)  # an affine matrix's


def _identity() -> np.ndarray:
    return np.eye(4, dtype=np.float32)[None]


@dataclass(eq=False)
class Skin(TrackedComponent):
    """The joint matrices (J, 4, 4) bending this entity's skinned mesh (see the module)."""

    SHAREABLE = False  # one entity's pose
    joint_matrices: np.ndarray = field(default_factory=_identity)
    skinning: str = "linear"

    def _validate(self, name: str, value: Any) -> Any:
        if name == "skinning":
            return choice(self, name, value, SKINNING_METHODS)
        if name != "joint_matrices":
            return value
        matrices = np.asarray(value) if isinstance(value, (np.ndarray, list, tuple)) else None
        if matrices is None or not np.issubdtype(matrices.dtype, np.number) or matrices.ndim != 3 \
                or matrices.shape[1:] != (4, 4) or not 1 <= len(matrices) <= MAX_JOINTS:
            shape = getattr(matrices, "shape", type(value).__name__)
            raise ComponentValueError(f"Skin.joint_matrices must be 1 to {MAX_JOINTS} (MAX_JOINTS) 4x4 matrices, a "
                                      f"numpy array of shape (J, 4, 4), got {shape}")
        matrices = np.array(matrices, np.float32)  # its own copy: an edit of the caller's array changes nothing
        largest = float(np.abs(matrices).max())  # (NaN where one is: it fails the test below)
        if not largest <= MAX_JOINT_VALUE:
            raise ComponentValueError(f"Skin.joint_matrices must be finite, within +-{MAX_JOINT_VALUE:g}")
        if float(np.abs(matrices[:, 3] - _BOTTOM_ROW).max()) > 1e-5:  # (a few numpy calls: a pose a frame)
            raise ComponentValueError("Skin.joint_matrices must be affine (each matrix's bottom row 0, 0, 0, 1; "
                                      "points are columns: M @ (x, y, z, 1))")
        matrices[:, 3] = _BOTTOM_ROW  # (within 1e-5 of it: made exact)
        world = getattr(self, "_world_ref", None)
        if world is not None:
            for entity in self._entities:
                world.check_invariants(entity, Skin, joint_matrices=matrices)
        return matrices


@dataclass(eq=False)
class Morph(TrackedComponent):
    """How much of each of its mesh's morph targets this entity wears: ``weights``, one a
    target (see the module), each within +-``MAX_MORPH_WEIGHT``."""

    SHAREABLE = False  # one entity's pose
    weights: tuple[float, ...] = ()

    def _validate(self, name: str, value: Any) -> Any:
        if name != "weights":
            return value
        try:
            weights = tuple(float(w) for w in value)
        except (TypeError, ValueError):
            raise ComponentValueError(f"Morph.weights must be numbers, one a morph target, got {value!r}") from None
        if any(isinstance(w, bool) for w in value) or len(weights) > MAX_MORPH_TARGETS \
                or not all(math.isfinite(w) and abs(w) <= MAX_MORPH_WEIGHT for w in weights):
            raise ComponentValueError(f"Morph.weights must be at most {MAX_MORPH_TARGETS} (MAX_MORPH_TARGETS) finite "
                                      f"numbers within +-{MAX_MORPH_WEIGHT:g}, got {value!r}")
        world = getattr(self, "_world_ref", None)
        if world is not None:
            for entity in self._entities:
                world.check_invariants(entity, Morph, weights=weights)
        return weights
