"""The water rule: a ``Water`` makes its entity's ``Mirror`` a water surface, so it needs a
Mirror on the same entity, and a sharp one (``Mirror.roughness`` 0: the waves break up the
image, not a blur).  Checked when the value is given (a spawn, an ``add_component``, a write
of ``Mirror.roughness``), as the world's invariants are, so the mistake is refused at the
line that makes it instead of stopping a later frame.  Level files check the same when they
load (``engine/assets/level_file.py``), naming the file and line."""
from __future__ import annotations

from typing import Any

from components import Material, Mirror, Ripples, Water
from components.tracking import ComponentValueError, warn_component
from engine.core.world import World, world_invariant


@world_invariant(Water, whole=True)
def check_water_has_mirror(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """A Water needs a Mirror on its entity (at the end of a spawn, whatever the order the
    components were listed in; on a later ``add_component``, the Mirror first)."""
    mirror = world.try_get(entity, Mirror) if world.exists(entity) else None
    if mirror is None:
        raise ComponentValueError(f"Water on entity {entity}: a Water needs a Mirror on the same entity (the "
                                  "surface it makes water); give the entity a Mirror(roughness=0) too")


@world_invariant(Ripples, Water, whole=True)
def check_ripples_on_water(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Ripples need a Water on their entity (the surface that ripples): at the end of a spawn,
    or on an ``add_component`` of Ripples (the Water first).  A Water taken off later leaves
    them still (the ripple stage finds no water there)."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None for kind in (Ripples, Water)}
    if joining is not None:
        held[type(joining)] = joining
    if held[Ripples] is not None and held[Water] is None:
        raise ComponentValueError(f"Ripples on entity {entity}: Ripples need a Water on the same entity (the "
                                  "surface that ripples); give the entity a Water (and its Mirror) too")


@world_invariant(Water, Mirror)
def check_water_is_sharp(world: World, entity: int, joining: Any = None, roughness: float | None = None,
                         **_other: Any) -> None:
    """A water's Mirror has roughness 0 (``roughness``: a value about to be written)."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None for kind in (Water, Mirror)}
    if joining is not None:
        held[type(joining)] = joining
    water, mirror = held[Water], held[Mirror]
    if water is None or mirror is None:
        return
    value = mirror.roughness if roughness is None else roughness
    if value > 0.0:
        raise ComponentValueError(f"Mirror.roughness on entity {entity} must be 0 with a Water (a water surface "
                                  f"is sharp: its waves break up the image, not a blur), got {value!r}")


@world_invariant(Water, whole=True)
def warn_still_water(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """A Water whose Material has no ``normal_map`` has no waves: a still, Fresnel-weighted
    mirror.  Allowed (a calm pond), but said once, as it is usually a forgotten map."""
    if joining is not None and not isinstance(joining, Water):
        return
    material = world.try_get(entity, Material) if world.exists(entity) else None
    if material is None or material.normal_map is None:
        warn_component(f"Water on entity {entity}: its Material has no normal_map, so the water has no waves (a "
                       "still, Fresnel-weighted mirror); give it one, e.g. Material(normal_map=wave_normal_map())")
