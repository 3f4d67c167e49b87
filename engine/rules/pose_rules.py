"""What a ``Skin`` and a ``Morph`` need of the mesh they pose, checked when either is given
(not frames later in the extract stage): a Skin a mesh with joints and weights a vertex and
a matrix for its highest joint; a Morph a mesh with morph targets and a weight for each;
neither on a mirror or a portal (their planes are read from the mesh as modelled, once)."""
from __future__ import annotations

from typing import Any

from components import Mirror, Portal
from components.pose import Morph, Skin
from components.rendering import MeshRef
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


def _posing(world: World, entity: int, kind: type, joining: Any, mesh: Any) -> tuple[Any, Any]:
    """``entity``'s ``kind`` (Skin or Morph) and the mesh it poses (``mesh``: one about to be
    set; None where it has none yet), as they will be once ``joining`` joins; a pose on a
    mirror or a portal refused."""
    exists = world.exists(entity)
    pose = joining if type(joining) is kind else world.try_get(entity, kind) if exists else None
    if pose is None:   # (most entities: nothing posed, nothing more to look up)
        return None, None
    held = {k: world.try_get(entity, k) if exists else None for k in (MeshRef, Mirror, Portal)}
    if joining is not None:
        held[type(joining)] = joining
    surface = "Mirror" if held[Mirror] is not None else "Portal" if held[Portal] is not None else None
    if pose is not None and surface is not None:
        raise ComponentValueError(f"entity {entity}: a {kind.__name__} on a {surface}: a mirror's or portal's plane is "
                                  "its mesh as modelled; pose a mesh in front of it instead")
    return pose, mesh if mesh is not None else getattr(held[MeshRef], "mesh", None)


@world_invariant(Skin, MeshRef, Mirror, Portal)
def check_skin(world: World, entity: int, joining: Any = None, joint_matrices: Any = None, mesh: Any = None,
               **_other: Any) -> None:
    """Refuse ``entity``'s Skin (``joint_matrices``: ones about to be set) on a mesh (``mesh``:
    one about to be set) without joints a vertex, or with a joint it has no matrix for."""
    skin, mesh = _posing(world, entity, Skin, joining, mesh)
    if skin is None or mesh is None:
        return
    matrices = joint_matrices if joint_matrices is not None else skin.joint_matrices
    if not mesh.skinned:
        raise ComponentValueError(f"entity {entity}: Skin on mesh {mesh.name!r}, which has no joints and weights a "
                                  "vertex (Mesh.joints, Mesh.weights): nothing for it to bend")
    if len(matrices) < mesh.joint_count:
        raise ComponentValueError(f"entity {entity}: Skin.joint_matrices holds {len(matrices)} matrices, but mesh "
                                  f"{mesh.name!r} names joints up to {mesh.joint_count - 1} (one matrix a joint)")


@world_invariant(Morph, MeshRef, Mirror, Portal)
def check_morph(world: World, entity: int, joining: Any = None, weights: Any = None, mesh: Any = None,
                **_other: Any) -> None:
    """Refuse ``entity``'s Morph (``weights``: ones about to be set) on a mesh (``mesh``: one
    about to be set) without morph targets, or with a count of targets not its weights'."""
    morph, mesh = _posing(world, entity, Morph, joining, mesh)
    if morph is None or mesh is None:
        return
    weights = weights if weights is not None else morph.weights
    if not mesh.morph_count:
        raise ComponentValueError(f"entity {entity}: Morph on mesh {mesh.name!r}, which has no morph targets "
                                  "(Mesh.morph_positions): nothing for its weights to weigh")
    if len(weights) != mesh.morph_count:
        raise ComponentValueError(f"entity {entity}: Morph.weights holds {len(weights)} weights, but mesh "
                                  f"{mesh.name!r} has {mesh.morph_count} morph targets (one weight a target)")
