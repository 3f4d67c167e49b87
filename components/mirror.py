"""A planar mirror on the entity's flat mesh (or on an explicit plane)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_VIEW_DEPTH
from components.tracking import ComponentValueError, TrackedComponent, boolean, color, finite, vec3


@dataclass(eq=False)
class Mirror(TrackedComponent):
    """Reflects the scene in the plane of its flat mesh (a virtual camera reflected in the plane,
    with an oblique near plane on it, as in Lengyel's "Oblique View Frustum" 2005).

    ``color`` tints the reflection, ``reflect_rate`` mixes it with the mirror's own shading,
    ``roughness`` blurs it (a mip bias on the reflection image), ``resolution_scale`` renders its reflection
    at a fraction of the screen's resolution (a level takes the largest scale among the
    mirrors it draws), ``max_depth`` limits mirrors seen in mirrors.  ``plane_point`` and
    ``plane_normal`` (model space) override the plane found from the mesh; a non-flat mesh
    without them is an error.
    """

    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    reflect_rate: float = 1.0
    roughness: float = 0.0
    resolution_scale: float = 1.0
    max_depth: int = 3
    enabled: bool = True
    plane_point: Any = None
    plane_normal: Any = None

    def _validate(self, name: str, value: Any) -> Any:
        if name == "color":
            return color(self, name, value)
        if name in ("reflect_rate", "roughness"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "resolution_scale":
            return finite(self, name, value, low=0.1, high=1.0)
        if name == "max_depth":
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= MAX_VIEW_DEPTH:
                raise ComponentValueError(f"Mirror.max_depth must be an int in [0, {MAX_VIEW_DEPTH}], got {value!r}")
        if name == "enabled":
            return boolean(self, name, value)
        if name == "plane_point" and value is not None:
            return vec3(self, name, value)
        if name == "plane_normal" and value is not None:
            return glm.normalize(vec3(self, name, value, nonzero=True))
        return value
