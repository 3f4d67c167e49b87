"""What a ``Refractive`` needs of its ``Material`` to show anything it bends: an alpha under 1.

A refracting surface blends the light it bends with the material's colour by the material's
alpha (``Refractive``: alpha 0 is clear glass, between 0 and 1 the colour tints it), so glass
on an opaque material (alpha 1, ``Material``'s default) draws the material's colour over all
of it and none of what lies behind: a look that costs a refraction and shows none.  Said
when the Refractive or the Material joins the entity (a ComponentWarning), not frames later
as a glass ball that came out white."""
from __future__ import annotations

from typing import Any

from components.rendering import Material, Refractive
from components.tracking import warn_component
from engine.core.world import World, world_invariant


@world_invariant(Refractive, Material)
def warn_opaque_glass(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Say a Refractive on an entity whose Material is opaque (alpha 1, no albedo texture whose
    alpha might open it, no cutout), as either joins."""
    if type(joining) not in (Refractive, Material):
        return  # (a field set: said when they joined)
    exists = world.exists(entity)
    glass = joining if type(joining) is Refractive else world.try_get(entity, Refractive) if exists else None
    material = joining if type(joining) is Material else world.try_get(entity, Material) if exists else None
    if glass is None or material is None:
        return
    if material.color[3] < 1.0 or material.texture is not None or material.alpha_cutoff is not None:
        return
    warn_component(f"Refractive on entity {entity}: its Material's alpha is 1, so the material's colour covers all "
                   "of it and none of what it bends shows; give the Material an alpha under 1 (0: clear glass, "
                   "between: tinted by its colour)")
