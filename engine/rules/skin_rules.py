"""What a ``Skin`` needs of the mesh it bends, checked when either is given (not frames
later in the extract stage): a mesh with joints and weights a vertex, a matrix for its
highest joint, and not a mirror's or a portal's (their planes are read from the mesh as
modelled, once)."""
from __future__ import annotations

from typing import Any

from components import Mirror, Portal
from components.rendering import MeshRef
from components.skin import Skin
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


@world_invariant(Skin, MeshRef, Mirror, Portal)
def check_skin(world: World, entity: int, joining: Any = None, joint_matrices: Any = None, mesh: Any = None,
               **_other: Any) -> None:
    """Refuse ``entity``'s Skin (``joint_matrices``: ones about to be set) on a mesh (``mesh``:
    one about to be set) without joints a vertex, or with a joint it has no matrix for."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None
            for kind in (Skin, MeshRef, Mirror, Portal)}
    if joining is not None:
        held[type(joining)] = joining
    skin, mesh_ref = held[Skin], held[MeshRef]
    if skin is None:
        return
    matrices = joint_matrices if joint_matrices is not None else skin.joint_matrices
    mesh = mesh if mesh is not None else getattr(mesh_ref, "mesh", None)
    surface = "Mirror" if held[Mirror] is not None else "Portal" if held[Portal] is not None else None
    if surface is not None:
        raise ComponentValueError(f"entity {entity}: a Skin on a {surface}: a mirror's or portal's plane is its mesh "
                                  "as modelled; bend a mesh in front of it instead")
    if mesh is None:
        return
    if not mesh.skinned:
        raise ComponentValueError(f"entity {entity}: Skin on mesh {mesh.name!r}, which has no joints and weights a "
                                  "vertex (Mesh.joints, Mesh.weights): nothing for it to bend")
    if len(matrices) < mesh.joint_count:
        raise ComponentValueError(f"entity {entity}: Skin.joint_matrices holds {len(matrices)} matrices, but mesh "
                                  f"{mesh.name!r} names joints up to {mesh.joint_count - 1} (one matrix a joint)")
