"""What an orthographic camera cannot have: the screen passes (``AmbientOcclusion``,
``ContactShadows``, ``ScreenReflections``) rebuild each pixel's position from a perspective depth image and march
rays in perspective screen space, so they are refused on one, when either is given (not
frames later in the screen stages, where they would darken and reflect the wrong places)."""
from __future__ import annotations

from typing import Any

from components import AmbientOcclusion, Camera, ContactShadows, ScreenReflections
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


@world_invariant(Camera, AmbientOcclusion, ContactShadows, ScreenReflections)
def check_screen_passes(world: World, entity: int, joining: Any = None, projection: Any = None,
                        **_other: Any) -> None:
    """Refuse ``entity``'s screen passes under an orthographic Camera (``projection``: one
    about to be set)."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None
            for kind in (Camera, AmbientOcclusion, ContactShadows, ScreenReflections)}
    if joining is not None:
        held[type(joining)] = joining
    camera = held[Camera]
    kind = projection if projection is not None else getattr(camera, "projection", "perspective")
    passes = [k.__name__ for k in (AmbientOcclusion, ContactShadows, ScreenReflections) if held[k] is not None]
    if camera is not None and kind == "orthographic" and passes:
        raise ComponentValueError(f"entity {entity}: {' and '.join(passes)} on an orthographic Camera: the screen "
                                  "passes rebuild positions from a perspective depth image (give the camera "
                                  "projection \"perspective\", or take them off)")
