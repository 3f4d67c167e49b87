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
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None for kind in (MeshRef, Material)}
    if joining is not None:
        held[type(joining)] = joining
    names = second_uv_maps if second_uv_maps is not None else getattr(held[Material], "second_uv_maps", ())
    mesh = mesh if mesh is not None else getattr(held[MeshRef], "mesh", None)
    if names and mesh is not None and mesh.second_uvs is None:
        raise ComponentValueError(f"entity {entity}: Material.second_uv_maps names {', '.join(names)}, but mesh "
                                  f"{mesh.name!r} has no second UV set (Mesh.second_uvs; a glTF's TEXCOORD_1)")
