"""A planar mirror on the entity's flat mesh (or on an explicit plane)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from components.tracking import (
    ComponentValueError,
    boolean,
    color,
    direction,
    end_image_choice,
    finite,
    integer,
    vec3,
)
from components.visibility import LAYER_FIELDS, ShownLayers


@dataclass(eq=False)
class Mirror(ShownLayers):
    """Reflects the scene in the plane of its flat mesh (a virtual camera reflected in the plane,
    with an oblique near plane on it, as in Lengyel's "Oblique View Frustum" 2005).  Not on an
    entity with a Portal (refused: ``mirror_rules.check_one_surface``), nor with a Reflective,
    Refractive or Emissive (refused: ``mirror_rules.check_surface_looks``; its look is
    ``color`` and ``reflect_rate``).

    ``color`` tints the reflection, ``reflect_rate`` mixes it with the mirror's own shading,
    ``roughness`` blurs it (a mip bias on the reflection image), ``resolution_scale`` renders its reflection
    at a fraction of the screen's resolution (a level takes the largest scale among the
    mirrors it draws), ``max_depth`` limits mirrors seen in mirrors.  ``plane_point`` and
    ``plane_normal`` (model space) override the plane found from the mesh; a non-flat mesh
    without them is an error.
    ``shows_layers`` (None: all) and ``hides_layers`` are the reflection layers its view
    shows (``components.visibility``): ``hides_layers=[3]`` shows all but layer 3.
    ``priority`` (an int, higher first; default 0) orders it under the frame's view budget
    (``engine.resources.ViewBudget``).
    ``end_image``: past the depth limit, show the surface's image from the previous frame,
    shrunk onto the cut view's footprint (``engine/render/end_images.py``), instead of its
    fallback: True, False, or "auto" (the default: on for a facing pair, whose recursion
    would otherwise end in the fallback's rectangle).

    Without a view of its own (cut by the frame's view budget, faded out, past the depth
    limits without an end image, or ``enabled`` False) a mirror shows its fallback: the
    reflection its surface would get from the probes whose influence boxes hold it, else
    from the sky, at its tint, reflect rate and roughness
    (``engine.rules.probe_rules.surface_blend``, ``engine/render/mirror_passes.py``).

    Fades (both off by default), as Unreal's planar reflections offer: ``fade_distance =
    (start, end)`` in metres from the viewing eye to the mirror (to its bounding sphere), and
    ``fade_angle = (start, end)`` in degrees between the mirror's normal and the direction to
    the eye (0: straight on, 90: edge on).  Between start and end the reflection's weight
    falls linearly from 1 to 0 and the mirror shows its fallback instead (the two mixed by the
    weight); at end and past it the mirror costs no view at all.  A view's weight is the product of the two, seen from
    that view's eye (a mirror seen in another mirror fades by the reflected eye's distance; one
    beyond a portal pair of two sizes by the carried eye's, in its own side's metres, so it
    fades at the size it looks, as it would seen there directly).

    ``reflects_light`` (off by default): the lights that reach its front are reflected onto
    what it faces, through its outline, tinted by ``color`` and scaled by ``reflect_rate``
    (a virtual light: the light's mirror image, with a shadow map of its own; one bounce;
    ``engine/rules/shadow_rules.py``); a ``Water``'s, also by Fresnel's reflectance at the
    angle the light meets it, as its reflection is weighed.
    """

    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    reflect_rate: float = 1.0
    roughness: float = 0.0
    resolution_scale: float = 1.0
    max_depth: int = 3
    enabled: bool = True
    priority: int = 0
    end_image: Any = "auto"
    plane_point: Any = None
    plane_normal: Any = None
    fade_distance: Any = None
    fade_angle: Any = None
    reflects_light: bool = False

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name in LAYER_FIELDS:
            return super()._validate(name, value)  # ShownLayers' check
        if name in ("reflect_rate", "roughness"):
            value = finite(self, name, value, low=0.0, high=1.0)
            world = getattr(self, "_world_ref", None)
            if name == "roughness" and world is not None:
                for entity in self._entities:  # a water's mirror stays sharp, checked at the write
                    world.check_invariants(entity, Mirror, roughness=value)
            return value
        if name == "resolution_scale":
            return finite(self, name, value, low=0.1, high=1.0)
        if name == "max_depth":
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= MAX_VIEW_DEPTH:
                raise ComponentValueError(f"Mirror.max_depth must be an int in [0, {MAX_VIEW_DEPTH}], got {value!r}")
        if name in ("enabled", "reflects_light"):
            return boolean(self, name, value)
        if name == "priority":
            return integer(self, name, value, low=-1000, high=1000)
        if name == "end_image":
            return end_image_choice(self, name, value)
        if name in ("fade_distance", "fade_angle") and value is not None:
            return _fade(name, value, 90.0 if name == "fade_angle" else None)
        if name == "plane_point" and value is not None:
            return vec3(self, name, value)
        if name == "plane_normal" and value is not None:
            return direction(self, name, value)
        return value


def _fade(name: str, value: Any, most: float | None) -> tuple[float, float]:
    """A fade's (start, end): two numbers (not text, not booleans), finite, 0 <= start < end
    (<= ``most``)."""
    parts = [] if isinstance(value, (str, bytes, dict)) else _parts(value)
    if len(parts) != 2 or any(isinstance(v, (str, bytes, bool, np.bool_)) for v in parts):
        raise ComponentValueError(f"Mirror.{name} must be None or two numbers (start, end), got {value!r}")
    try:
        start, end = (float(v) for v in parts)
    except (TypeError, ValueError, OverflowError):
        raise ComponentValueError(f"Mirror.{name} must be None or two numbers (start, end), got {value!r}") from None
    limit = f" <= {most:g}" if most is not None else ""
    if not (0.0 <= start < end and end < float("inf") and (most is None or end <= most)):
        raise ComponentValueError(f"Mirror.{name} must have 0 <= start < end{limit}, got {value!r}")
    return start, end


def _parts(value: Any) -> list[Any]:
    try:
        return list(value)
    except TypeError:
        return []
