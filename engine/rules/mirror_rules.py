"""What makes a mesh a mirror: one rule, registered with every world as an invariant
(``engine.core.world.world_invariant``), so a bad mirror is refused when it is made, not
on the next frame inside the surfaces stage.

A mirror needs a mesh with area (its plane comes from it, unless ``Mirror.plane_normal``
gives one) that is flat; a mirror with a normal map needs UVs that vary linearly over its
plane (``engine.assets.mesh.planar_uv_map``).  Checked when a Mirror, MeshRef or Material
joins an entity holding the others, when a mirror's ``MeshRef.mesh`` is replaced and when
its ``Material.normal_map`` is set.  The surfaces stage fits the same plane and UVs.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from components import ComponentValueError, Material, MeshRef, Mirror
from engine.assets.mesh import Mesh, flat_plane, planar_uv_map
from engine.core.world import World, world_invariant


@world_invariant(Mirror, MeshRef, Material)
def check_mirror_mesh(world: World, entity: int, joining: Any = None, mesh: Mesh | None = None,
                      normal_map: Any = None) -> None:
    """Refuse ``entity`` as a mirror when its mesh (``mesh``: a replacement about to be set)
    or, with a normal map (``normal_map``: one about to be set), its UVs cannot make one."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None for kind in (Mirror, MeshRef, Material)}
    if joining is not None:
        held[type(joining)] = joining
    mirror, mesh_ref, material = held[Mirror], held[MeshRef], held[Material]
    if mesh is None and mesh_ref is not None:
        mesh = mesh_ref.mesh
    if mirror is None or mesh is None:
        return
    if (normal_map or getattr(material, "normal_map", None)) is not None:
        rows, why = planar_uv_map(mesh)
        if rows is None:
            raise ComponentValueError(
                f"Mirror on entity {entity}: Material.normal_map needs UVs that vary linearly over the mirror "
                f"(mesh {mesh.name!r}: {why}); use a flat mesh with planar UVs, such as a quad")
    if mirror.plane_normal is not None:
        return
    tri = mesh.positions[mesh.indices]
    area = float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    if not area > 0.0:
        raise ComponentValueError(f"Mirror on entity {entity}: its MeshRef.mesh {mesh.name!r} has no area "
                                  f"(a mirror needs a flat mesh of non-zero size), got area {area}")
    if flat_plane(mesh) is None:
        lo, hi = mesh.bounds
        raise ComponentValueError(
            f"Mirror on entity {entity}: its MeshRef.mesh {mesh.name!r} which is not flat (model-space "
            f"extents {[round(float(v), 3) for v in hi - lo]}); give the mirror a flat mesh or plane_normal")
