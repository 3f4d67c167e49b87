"""What ``Material.second_uv_maps`` needs of the mesh: a second UV set (``Mesh.second_uvs``),
checked when the Material or the mesh is given (not frames later in the extract stage,
where the shader would read zeros for it and paint the map's corner texel everywhere)."""
from __future__ import annotations

from typing import Any

from components.rendering import Material, MeshRef
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


@world_invariant(MeshRef, Material)
def check_second_uvs(world: World, entity: int, joining: Any = None, mesh: Any = None,
                     second_uv_maps: Any = None, **_other: Any) -> None:
    """Refuse ``entity``'s Material naming maps of the second UV set (``second_uv_maps``: ones
    about to be set) on a mesh (``mesh``: one about to be set) without one."""
    exists = world.exists(entity)
    if second_uv_maps is None:
        material = joining if type(joining) is Material else world.try_get(entity, Material) if exists else None
        second_uv_maps = getattr(material, "second_uv_maps", ())
    names = second_uv_maps
    if not names:
        return  # (most materials: no map on the second UV set, nothing more to look up)
    if mesh is None:
        mesh_ref = joining if type(joining) is MeshRef else world.try_get(entity, MeshRef) if exists else None
        mesh = getattr(mesh_ref, "mesh", None)
    if names and mesh is not None and mesh.second_uvs is None:
        raise ComponentValueError(f"entity {entity}: Material.second_uv_maps names {', '.join(names)}, but mesh "
                                  f"{mesh.name!r} has no second UV set (Mesh.second_uvs; a glTF's TEXCOORD_1)")
