"""What a camera's components need.  An orthographic camera cannot have the screen passes
(``AmbientOcclusion``, ``ContactShadows``, ``ScreenReflections``): they rebuild each pixel's
position from a perspective depth image and march rays in perspective screen space, so they
are refused on one, when either is given (not frames later in the screen stages, where they
would darken and reflect the wrong places).  And every component a camera reads from its own
entity (the screen passes, fog and the post chain) does nothing on an entity without a
Camera: said (a ComponentWarning) when it is spawned or joins one, not left to be found as
an effect that never shows."""
from __future__ import annotations

from typing import Any

from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    ChromaticAberration,
    ColorGrading,
    ContactShadows,
    DepthOfField,
    FilmGrain,
    Fog,
    LensFlare,
    MotionBlur,
    ScreenReflections,
    Tonemap,
    Vignette,
    VolumetricFog,
)
from components.tracking import ComponentValueError, warn_component
from engine.core.world import World, world_invariant

# The components a camera reads from its own entity (and nothing reads elsewhere).
CAMERA_COMPONENTS = (AmbientOcclusion, ContactShadows, ScreenReflections, Fog, VolumetricFog, Tonemap, Bloom,
                     ColorGrading, Vignette, DepthOfField, MotionBlur, LensFlare, ChromaticAberration, FilmGrain)


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


@world_invariant(*CAMERA_COMPONENTS, whole=True)
def warn_camera_component_without_camera(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Say a camera's component (CAMERA_COMPONENTS) on an entity without a Camera, at the end
    of its spawn or as it joins: a camera reads it from its own entity, so there it does nothing."""
    if joining is not None and not isinstance(joining, CAMERA_COMPONENTS):
        return  # (a field set: said when it came)
    if not world.exists(entity) or world.try_get(entity, Camera) is not None:
        return
    kinds = [kind.__name__ for kind in CAMERA_COMPONENTS
             if (joining if type(joining) is kind else world.try_get(entity, kind)) is not None]
    if kinds:
        warn_component(f"{', '.join(kinds)} on entity {entity}, which has no Camera: a camera reads "
                       f"{'it' if len(kinds) == 1 else 'them'} from its own entity, so here "
                       f"{'it does' if len(kinds) == 1 else 'they do'} nothing; put "
                       f"{'it' if len(kinds) == 1 else 'them'} on the camera's entity")
