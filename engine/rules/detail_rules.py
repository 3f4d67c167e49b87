"""The level-of-detail rule: a ``LevelOfDetail`` swaps its entity's ``MeshRef.mesh``, so it
needs a MeshRef on the same entity, and is refused on a Mirror or Portal (their mesh is the
surface the view tree plans: a swap would move the mirror).  Checked when the value is given,
as the world's invariants are, so the mistake is refused at the line that makes it."""
from __future__ import annotations

from typing import Any

from components import MeshRef, Mirror, Portal
from components.detail import LevelOfDetail
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


@world_invariant(LevelOfDetail, whole=True)
def check_detail_has_mesh(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """A LevelOfDetail needs a MeshRef on its entity (whose mesh it swaps)."""
    if world.exists(entity) and world.try_get(entity, MeshRef) is None:
        raise ComponentValueError(f"LevelOfDetail on entity {entity}: it swaps the entity's MeshRef.mesh; give the "
                                  "entity a MeshRef too (its finest mesh)")


@world_invariant(LevelOfDetail, Mirror, Portal)
def check_detail_not_on_surface(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """No LevelOfDetail on a mirror or portal."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None
            for kind in (LevelOfDetail, Mirror, Portal)}
    if joining is not None:
        held[type(joining)] = joining
    surface = held[Mirror] or held[Portal]
    if held[LevelOfDetail] is not None and surface is not None:
        raise ComponentValueError(f"LevelOfDetail on entity {entity}: a {type(surface).__name__}'s mesh is its "
                                  "surface, which the view tree plans; give the mirror or portal one mesh")
