"""What a camera's light shafts (``VolumetricFog``) are drawn with, or why it has none: shared
by the main view (the active camera, ``systems/main_view_system.py``) and the monitors (a
``Monitor``'s camera, ``systems/monitor_system.py``), so a camera's shafts are the same
whichever view it draws (``engine/render/volumetric_fog.py``)."""
from __future__ import annotations

from dataclasses import dataclass

from components.fog import Fog, VolumetricFog
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.render.sky import air_light
from engine.resources import VolumetricLamps
from engine.rules.light_rules import KeptLights
from engine.rules.shadow_rules import ShadowCasters

_NO_LAMPS = VolumetricLamps()


@dataclass(frozen=True)
class CameraShafts:
    """A camera's ``VolumetricFog`` (``settings``) and what lights its air: the lamps it
    scatters (the prepare stage's ``VolumetricLamps``), the sun's or moon's slot in the Lights
    block and the unit way towards it (``sky_light``; None: neither), and each light through
    a mirror or portal's share (``image_shares``, by its virtual slot: ``image_shares``)."""

    settings: VolumetricFog
    lamps: VolumetricLamps
    sky_light: tuple[int, tuple[float, float, float]] | None
    image_shares: tuple[float, ...]


def camera_shafts(world: World, renderer: Renderer, camera: int, fog: Fog | None
                  ) -> tuple[CameraShafts | None, str | None]:
    """The shafts of ``camera`` (an entity), whose air is ``fog`` (its own ``Fog``, or the one
    its view is drawn through), and None; or None and why it adds nothing (its air is empty, or
    no light lights it: the caller says so once); (None, None) where it has no ``VolumetricFog``."""
    settings = world.try_get(camera, VolumetricFog)
    if settings is None:
        return None, None
    if (fog is None or fog.density <= 0.0) and not renderer.fog.volume_count:
        return None, "has no Fog with a density beside it and no FogVolume stands (the shafts are its air's light)"
    lamps = world.resources.get(VolumetricLamps, _NO_LAMPS)
    lit_by = air_light(world)   # (the sun, or the moon by night)
    if lit_by is None and not lamps.slots:
        return None, ("lights its air with the sun or the moon and the lamps with volumetric > 0, and the world has "
                      "no DirectionalLight that shines and no such PointLight")
    kept = world.resources.get(KeptLights)
    slot = kept.directional.index(lit_by.entity) \
        if lit_by is not None and kept is not None and lit_by.entity in kept.directional else None
    return CameraShafts(settings, lamps, None if slot is None else (slot, lit_by.towards),
                        image_shares(world, None if slot is None else lit_by.entity, lamps, kept)), None


def image_shares(world: World, air: int | None, lamps: VolumetricLamps, kept: KeptLights | None) -> tuple[float, ...]:
    """Each light through a mirror or portal this frame (the shadows stage's
    ``ShadowCasters.virtual``, by slot): its share of the shafts, its light's: 1 for the
    image of the sun or moon that lights the air (``air``), a scattered lamp's
    ``volumetric`` for the lamp's (one of ``lamps``: those past the limit scatter neither),
    0 for the rest."""
    casters = world.resources.get(ShadowCasters)
    if casters is None or not casters.virtual:
        return ()
    scattered = {kept.point[slot]: share for slot, share in zip(lamps.slots, lamps.scatter, strict=True)} \
        if kept is not None else {}
    return tuple(1.0 if light.kind == "directional" and light.light == air
                 else scattered.get(light.light, 0.0) if light.kind == "point" else 0.0
                 for light in casters.virtual)
