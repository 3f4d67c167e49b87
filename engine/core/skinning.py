"""Linear blend skinning and morph targets: a vertex moved by up to four joints, each weighing
its share, after its morph targets' offsets, each weighed by its weight.

A skinned mesh (``Mesh.joints``, ``Mesh.weights``: glTF's JOINTS_0 and WEIGHTS_0) is bent by
its ``Skin``'s joint matrices: each one a joint's pose times its inverse bind matrix, in the
mesh's own space, so a joint at rest gives the identity.  A vertex goes to
``sum_i weight_i x joint_matrix[joint_i] x position`` (its normal by the inverse transpose of
that blend), as every real-time engine since Quake III's MD4 has drawn characters.  The GPU
does it in ``shaders/include/pose.glsl`` for every view and shadow map; this module is
the same sum on arrays, for what the CPU needs: a ray cast against the posed triangles, and
the box that holds the pose (what culling and the shadow maps' redraws read).

A morph target (``Mesh.morph_positions``, ``morph_normals``: glTF's ``targets``, a face's
smile, a door's dent) is an offset a vertex; a ``Morph``'s weights say how much of each is
added (``shaders/include/pose.glsl``), before the joints bend the result.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from components.limits import MAX_JOINTS


class PosedMesh(Protocol):
    """What posing reads of a mesh (``engine.assets.mesh.Mesh`` has it; the core does not
    import the assets, which build on it)."""

    positions: np.ndarray
    joints: np.ndarray | None
    weights: np.ndarray | None
    morph_positions: np.ndarray | None

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]: ...

    def joint_boxes(self) -> np.ndarray: ...

    def morph_offset_boxes(self) -> np.ndarray: ...


__all__ = ["INFLUENCES", "MAX_JOINTS", "PosedMesh", "blend_matrices", "dual_quaternion_matrices", "joint_boxes",
           "joint_dual_quaternions", "joint_rotations", "morph_reach", "morphed", "posed_bounds", "posed_box",
           "posed_positions", "skin_positions", "strongest_influences"]

INFLUENCES = 4              # joints a vertex may follow (glTF's JOINTS_0: more are folded into the four largest)


def blend_matrices(joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray,
                   dual_quaternion: bool = False) -> np.ndarray:
    """Each vertex's blended matrix (V, 4, 4): its joints' matrices weighed by its weights, or
    (``dual_quaternion``) their rotations and translations blended as dual quaternions
    (``dual_quaternion_matrices``)."""
    if dual_quaternion:
        return dual_quaternion_matrices(joints, weights, matrices)
    return np.einsum("vi,virc->vrc", weights.astype(np.float64), matrices.astype(np.float64)[joints])


def _quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) as (x, y, z, w), multiplied."""
    vector = a[..., 3:] * b[..., :3] + b[..., 3:] * a[..., :3] + np.cross(a[..., :3], b[..., :3])
    return np.concatenate([vector, a[..., 3:] * b[..., 3:] - (a[..., :3] * b[..., :3]).sum(-1, keepdims=True)], -1)


def _rotation_quaternions(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices (N, 3, 3), each from its largest
    diagonal term (Shepperd's method)."""
    trace = r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    cases = [np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1], trace + 1.0], -1),
             np.stack([1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2], r[:, 0, 1] + r[:, 1, 0], r[:, 0, 2] + r[:, 2, 0],
                       r[:, 2, 1] - r[:, 1, 2]], -1),
             np.stack([r[:, 0, 1] + r[:, 1, 0], 1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2], r[:, 1, 2] + r[:, 2, 1],
                       r[:, 0, 2] - r[:, 2, 0]], -1),
             np.stack([r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1], 1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1],
                       r[:, 1, 0] - r[:, 0, 1]], -1)]
    pick = np.where(trace > 0.0, 0, np.where((r[:, 0, 0] >= r[:, 1, 1]) & (r[:, 0, 0] >= r[:, 2, 2]), 1,
                                             np.where(r[:, 1, 1] >= r[:, 2, 2], 2, 3)))
    q = np.stack(cases)[pick, np.arange(len(r))]
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def joint_rotations(linear: np.ndarray) -> np.ndarray:
    """Each joint's rotation (J, 3, 3) from its matrix's linear part (J, 3, 3), the Q of its QR
    decomposition by Gram-Schmidt: x its first column's way, y its second's less its x, z = x
    cross y (so a mirrored joint's rotation is proper and its stretch holds the flip).  A
    column squashed to nothing (a joint scaled flat) is replaced: x by the other two's cross
    product, else the x axis; y by a way square to x.  Whatever the rotation, the joint's
    stretch (``joint_dual_quaternions``) makes it exact: rotation x stretch is the matrix."""
    linear = np.asarray(linear, np.float64)
    tiny = 1e-9 * np.abs(linear).max(axis=(1, 2), initial=0.0)[:, None]
    x = linear[:, :, 0]
    x = np.where(np.linalg.norm(x, axis=-1, keepdims=True) > tiny, x, np.cross(linear[:, :, 1], linear[:, :, 2]))
    x = np.where(np.linalg.norm(x, axis=-1, keepdims=True) > tiny * tiny, x, [1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = linear[:, :, 1] - (linear[:, :, 1] * x).sum(-1, keepdims=True) * x
    square = np.cross(x, np.where(np.abs(x[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    y = np.where(np.linalg.norm(y, axis=-1, keepdims=True) > tiny, y, square)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], -1)


def joint_dual_quaternions(matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each joint matrix (J, 4, 4) as a unit dual quaternion (real (J, 4), dual (J, 4), as
    (x, y, z, w)) and a stretch (J, 3, 3): its linear part L as a rotation R
    (``joint_rotations``) after a stretch S = R^T L (its scale and shear, uneven or not: the
    identity for a rigid joint, s I for a uniform scale s), so the matrix is the turn and
    move (R, its last column) of the stretched point (``shaders/include/pose.glsl``
    joint_dual_quaternion)."""
    m = np.asarray(matrices, np.float64)
    linear = m[:, :3, :3]
    rotation = joint_rotations(linear)
    real = _rotation_quaternions(rotation)
    translation = np.concatenate([m[:, :3, 3], np.zeros((len(m), 1))], -1)
    return real, 0.5 * _quaternion_product(translation, real), np.einsum("jrc,jrk->jck", rotation, linear)


def dual_quaternion_matrices(joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """Each vertex's matrix (V, 4, 4) by dual quaternion skinning (Kavan, Collins, Zara and
    O'Sullivan 2008; ``Skin.skinning`` "dual_quaternion") with its joints' stretches blended
    apart, the two-phase blend of their section on non-rigid joints (Blender's and Maya's DQ
    with scale): its joints' dual quaternions (``joint_dual_quaternions``) each turned into
    its first joint's hemisphere, summed by weight and normalised, its rotation and
    translation, applied after its joints' stretches summed by weight.  So a joint squashed
    and stretched unevenly bends its vertices as its matrix does, and joints that only
    stretch and move blend as linear skinning does (``shaders/include/pose.glsl``'s
    skin_matrix in that build)."""
    real, dual, stretch = joint_dual_quaternions(matrices)
    w = weights.astype(np.float64)
    r, d = real[joints], dual[joints]                                  # (V, 4 joints, 4)
    signed = np.where((r * r[:, :1]).sum(-1) < 0.0, -w, w)             # the first joint's hemisphere
    blend_real, blend_dual = np.einsum("vi,vik->vk", signed, r), np.einsum("vi,vik->vk", signed, d)
    norm = np.linalg.norm(blend_real, axis=-1, keepdims=True)
    q, qd = blend_real / norm, blend_dual / norm
    translation = 2.0 * (q[:, 3:] * qd[:, :3] - qd[:, 3:] * q[:, :3] + np.cross(q[:, :3], qd[:, :3]))
    x, y, z, s = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    rotation = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - s * z), 2 * (x * z + s * y)], -1),
                         np.stack([2 * (x * y + s * z), 1 - 2 * (x * x + z * z), 2 * (y * z - s * x)], -1),
                         np.stack([2 * (x * z - s * y), 2 * (y * z + s * x), 1 - 2 * (x * x + y * y)], -1)], 1)
    out = np.zeros((len(joints), 4, 4))
    out[:, :3, :3] = rotation @ np.einsum("vi,virc->vrc", w, stretch[joints])
    out[:, :3, 3] = translation
    out[:, 3, 3] = 1.0
    return out


def skin_positions(positions: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                   matrices: np.ndarray, dual_quaternion: bool = False) -> np.ndarray:
    """Where each vertex goes (V, 3, float64) under the joint ``matrices`` (J, 4, 4), blended
    linearly or as dual quaternions."""
    blended = blend_matrices(joints, weights, matrices, dual_quaternion)
    return np.einsum("vrc,vc->vr", blended[:, :3, :3], positions.astype(np.float64)) + blended[:, :3, 3]


def joint_boxes(positions: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                joint_count: int) -> np.ndarray:
    """For each joint (``joint_count``), the box (2, 3) of the vertices it moves at all (a
    weight above 0); NaN for a joint that moves none.  A posed vertex lies in the convex
    hull of its joints' images of it (the weights are non-negative and sum to 1), so the
    union of each joint's box placed by its matrix holds the whole pose (``posed_box``)."""
    boxes = np.full((joint_count, 2, 3), np.nan)
    used = weights > 0.0
    flat_joints = joints[used]
    flat_points = np.repeat(positions[:, None, :], joints.shape[1], axis=1)[used].astype(np.float64)
    if len(flat_joints):
        lo = np.full((joint_count, 3), np.inf)
        hi = np.full((joint_count, 3), -np.inf)
        np.minimum.at(lo, flat_joints, flat_points)
        np.maximum.at(hi, flat_joints, flat_points)
        moving = np.isfinite(lo[:, 0])
        boxes[moving, 0], boxes[moving, 1] = lo[moving], hi[moving]
    return boxes


def posed_box(boxes: np.ndarray, matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) holding a pose: each joint's box (``joint_boxes``) placed by its
    matrix, axis by axis (the lower of ``lo_c x M[r][c]`` and ``hi_c x M[r][c]`` summed, plus the
    translation), and their union."""
    moving = ~np.isnan(boxes[:, 0, 0])  # (matrices past the mesh's highest joint move nothing)
    boxes, placed = boxes[moving], matrices[: len(moving)].astype(np.float64)[moving]
    if not len(boxes):
        return np.zeros(3), np.zeros(3)
    terms = placed[:, None, :3, :3] * boxes[:, :, None, :]  # [joint, lo/hi, row, column]
    low = np.minimum(terms[:, 0], terms[:, 1]).sum(axis=2) + placed[:, :3, 3]
    high = np.maximum(terms[:, 0], terms[:, 1]).sum(axis=2) + placed[:, :3, 3]
    return low.min(axis=0), high.max(axis=0)


def strongest_influences(joints: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A vertex's ``INFLUENCES`` largest weights and their joints, the weights made to sum to 1
    (glTF's JOINTS_1 and WEIGHTS_1 sets fold in here; Unity's "four bones" does the same);
    fewer columns are padded with joint 0 at weight 0."""
    joints = np.asarray(joints)
    weights = np.asarray(weights, np.float64)
    if joints.shape[1] < INFLUENCES:
        pad = INFLUENCES - joints.shape[1]
        joints = np.hstack([joints, np.zeros((len(joints), pad), joints.dtype)])
        weights = np.hstack([weights, np.zeros((len(weights), pad))])
    if joints.shape[1] > INFLUENCES:
        order = np.argsort(-weights, axis=1, kind="stable")[:, :INFLUENCES]
        joints = np.take_along_axis(joints, order, axis=1)
        weights = np.take_along_axis(weights, order, axis=1)
    total = weights.sum(axis=1, keepdims=True)
    return joints, weights / np.where(total > 0.0, total, 1.0)


def morphed(base: np.ndarray, offsets: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``base`` (V, 3) plus each target's ``offsets`` (T, V, 3) times its weight (T), float64."""
    return base.astype(np.float64) + np.einsum("t,tvc->vc", np.asarray(weights, np.float64),
                                                offsets.astype(np.float64))


def morph_reach(offset_boxes: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far the weighted targets can move any vertex, a box (lo, hi) to add to the mesh's:
    each target's box of offsets (T, 2, 3) scaled by its weight (a negative one swaps its
    ends), summed axis by axis."""
    scaled = offset_boxes.astype(np.float64) * np.asarray(weights, np.float64)[:, None, None]
    return np.minimum(scaled[:, 0], scaled[:, 1]).sum(axis=0), np.maximum(scaled[:, 0], scaled[:, 1]).sum(axis=0)


def posed_bounds(mesh: PosedMesh, joint_matrices: np.ndarray | None,
                 morph_weights: np.ndarray | None, dual_quaternion: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) holding ``mesh`` posed (``posed_positions``' points): its box, or each
    joint's (``joint_boxes``), grown by how far the weighed targets reach (``morph_reach``),
    then placed by the joints (``posed_box``).  Dual quaternion skinning turns a vertex along
    an arc between its joints' images of it, outside their hull: its box is its posed
    vertices' own (``posed_positions``, every vertex)."""
    if dual_quaternion and joint_matrices is not None:
        points = posed_positions(mesh, joint_matrices, morph_weights, dual_quaternion=True)
        return points.min(axis=0), points.max(axis=0)
    if morph_weights is None:
        return mesh.bounds if joint_matrices is None else posed_box(mesh.joint_boxes(), joint_matrices)
    low, high = morph_reach(mesh.morph_offset_boxes(), morph_weights)
    if joint_matrices is None:
        lo, hi = mesh.bounds
        return lo + low, hi + high
    return posed_box(mesh.joint_boxes() + np.stack([low, high])[None], joint_matrices)


def posed_positions(mesh: PosedMesh, joint_matrices: np.ndarray | None, morph_weights: np.ndarray | None,
                    dual_quaternion: bool = False) -> np.ndarray:
    """Where ``mesh``'s vertices go (V, 3, float64): its morph targets weighed in, then bent
    by its joints (either None: not applied; ``dual_quaternion``: blended as dual
    quaternions), as the SKINNED and MORPHED builds draw it."""
    positions = mesh.positions.astype(np.float64)
    if morph_weights is not None:
        positions = morphed(positions, mesh.morph_positions, morph_weights)
    if joint_matrices is not None:
        positions = skin_positions(positions, mesh.joints, mesh.weights, joint_matrices, dual_quaternion)
    return positions
